"""Encode chat conversations with images for a transformers VLM, and batched greedy generation.

Conventions:

* a conversation is a list of HF chat messages, ``{"role": "system" | "user" | "assistant",
  "content": str | [{"type": "image"}, {"type": "text", "text": ...}, ...]}``;
* ``images[i]`` lists the images of conversation ``i`` in the order of its ``{"type": "image"}``
  entries: uint8 H×W×3 RGB numpy arrays (or C×H×W uint8 tensors, or PIL images). It may be
  empty (a text-only conversation), and counts may differ between conversations;
* batches are padded on the left, so every row's generation starts at the same position.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import torch
from PIL import Image

from spacedg.errors import InvalidDataError, ParameterError

__all__ = ["encode_chats", "generate", "to_pil"]


def to_pil(image: Any) -> Image.Image:
    """A uint8 H×W×3 numpy array, a uint8 C×H×W torch tensor or a PIL image → an RGB PIL image."""
    if isinstance(image, Image.Image):
        return image.convert("RGB")
    if isinstance(image, torch.Tensor):
        if image.ndim != 3 or image.shape[0] != 3:
            raise InvalidDataError(f"image tensor must be C×H×W with C=3, got shape {tuple(image.shape)}")
        image = image.detach().cpu().permute(1, 2, 0).numpy()
    array = np.asarray(image)
    if array.dtype != np.uint8 or array.ndim != 3 or array.shape[2] != 3:
        raise InvalidDataError(f"image must be uint8 H×W×3 RGB, got {array.dtype} of shape {array.shape}")
    return Image.fromarray(np.ascontiguousarray(array), mode="RGB")


def _image_entries(conversation: Sequence[dict[str, Any]]) -> int:
    count = 0
    for message in conversation:
        content = message.get("content")
        if not isinstance(content, str):
            count += sum(1 for part in content or () if part.get("type") == "image")
    return count


def encode_chats(processor: Any, conversations: Sequence[Sequence[dict[str, Any]]], images: Sequence[Sequence[Any]],
                 *, add_generation_prompt: bool = True, return_assistant_mask: bool = False) -> Any:
    """Tokenize ``conversations`` with their ``images`` (see module doc) into one padded batch.

    Returns the processor's ``BatchFeature`` of torch tensors (``input_ids``, ``attention_mask``,
    the pixel inputs when any image is present, ...), padded on the left. With
    ``return_assistant_mask`` it also holds ``assistant_masks`` (1 on the tokens of assistant
    answers and their end-of-turn token, as marked by the chat template's generation blocks).
    """
    if len(conversations) != len(images):
        raise ParameterError(f"{len(conversations)} conversations but {len(images)} image lists; give one "
                             f"(possibly empty) image list per conversation")
    if not conversations:
        raise ParameterError("encode_chats needs at least one conversation")
    for i, (conversation, imgs) in enumerate(zip(conversations, images)):
        if (n := _image_entries(conversation)) != len(imgs):
            raise ParameterError(f"conversation {i} has {n} image entries but {len(imgs)} images were given")
    nested = [[to_pil(image) for image in imgs] for imgs in images]
    flat = [image for imgs in nested for image in imgs]
    processor.tokenizer.padding_side = "left"
    chats = [list(c) for c in conversations]
    if return_assistant_mask:
        kwargs: dict[str, Any] = {"padding": True}
        if flat:  # apply_chat_template wants them nested per conversation
            kwargs["images"] = nested
        return processor.apply_chat_template(chats, add_generation_prompt=add_generation_prompt, tokenize=True,
                                             return_dict=True, return_assistant_tokens_mask=True,
                                             return_tensors="pt", processor_kwargs=kwargs)
    texts = processor.apply_chat_template(chats, add_generation_prompt=add_generation_prompt, tokenize=False)
    return processor(text=texts, images=flat or None, padding=True, return_tensors="pt")


def generate(model: Any, processor: Any, conversations: Sequence[Sequence[dict[str, Any]]],
             images: Sequence[Sequence[Any]], *, max_new_tokens: int = 64, do_sample: bool = False,
             **gen_kwargs: Any) -> list[str]:
    """Answer every conversation in one batched ``model.generate`` call (greedy by default).

    Returns the newly generated text of each conversation, in order, special tokens skipped.
    Pad id: the tokenizer's. Stop ids: the tokenizer's eos plus the model's generation-config
    eos ids (e.g. Qwen's ``<|im_end|>`` and ``<|endoftext|>``); ``gen_kwargs`` override both.
    """
    tokenizer = processor.tokenizer
    configured = getattr(getattr(model, "generation_config", None), "eos_token_id", None)
    configured = [configured] if isinstance(configured, int) else list(configured or [])
    eos = [i for i in dict.fromkeys([tokenizer.eos_token_id, *configured]) if i is not None]
    batch = encode_chats(processor, conversations, images).to(model.device)
    if "pixel_values" in batch and batch["pixel_values"].is_floating_point():
        batch["pixel_values"] = batch["pixel_values"].to(model.dtype)
    settings = {"max_new_tokens": max_new_tokens, "do_sample": do_sample, "pad_token_id": tokenizer.pad_token_id,
                "eos_token_id": eos, **gen_kwargs}
    with torch.inference_mode():
        out = model.generate(**batch, **settings)
    new = out[:, batch["input_ids"].shape[1]:]
    return tokenizer.batch_decode(new, skip_special_tokens=True)

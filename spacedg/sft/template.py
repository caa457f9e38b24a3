"""A chat template that marks assistant answers, for the assistant-only loss.

Assistant-only labels come from ``apply_chat_template(..., return_assistant_tokens_mask=True)``,
which needs ``{% generation %}`` blocks in the template. The stock Qwen-VL and InternVL
templates have none, so :func:`ensure_generation_markers` swaps in spacedg's Qwen2.5-VL-style
template (:data:`spacedg.vlm.tiny.CHAT_TEMPLATE`, the same ``<|im_start|>role … <|im_end|>``
layout) with the family's image placeholder. The processor, template included, is saved into
every checkpoint, so inference with ``spacedg predict`` sees the exact training layout.
"""

from __future__ import annotations

from typing import Any

from spacedg.vlm.tiny import CHAT_TEMPLATE, IMAGE_PLACEHOLDERS

__all__ = ["ensure_generation_markers"]


def ensure_generation_markers(processor: Any) -> bool:
    """Give ``processor`` a template with generation blocks when it lacks them; returns whether it changed."""
    template = getattr(processor, "chat_template", None) or ""
    if "{% generation %}" in template or "{%- generation %}" in template:
        return False
    family = "internvl" if "InternVL" in type(processor).__name__ else "qwen"
    processor.chat_template = CHAT_TEMPLATE.replace("{image}", IMAGE_PLACEHOLDERS[family])
    return True

"""Local transformers vision-language models: loading, chat encoding, batched generation.

* :mod:`spacedg.vlm.loading`: :func:`load_vlm` / :func:`load_processor` (and the one
  workaround for transformers processors without torchvision);
* :mod:`spacedg.vlm.generate`: :func:`encode_chats`, :func:`generate`, :func:`to_pil`;
* :mod:`spacedg.vlm.tiny`: real tiny VLMs built offline (:func:`build_tiny_vlm`,
  :func:`save_tiny_vlm`) for tests and smoke runs.
"""

from spacedg.vlm.generate import encode_chats, generate, to_pil
from spacedg.vlm.loading import load_processor, load_vlm, pixel_budget
from spacedg.vlm.tiny import TINY_FAMILIES, build_tiny_vlm, save_tiny_vlm

__all__ = ["TINY_FAMILIES", "build_tiny_vlm", "encode_chats", "generate", "load_processor", "load_vlm",
           "pixel_budget", "save_tiny_vlm", "to_pil"]

"""The one no-torchvision workaround: build a VLM processor with a placeholder video processor.

transformers (checked with 5.23) constructs a Qwen-VL / InternVL processor only when torchvision
imports (see :mod:`spacedg.vlm.loading` for the whole story); :func:`assemble_processor` skips
that one class check for one instance. Images work exactly as with the stock processor.
"""

from __future__ import annotations

from typing import Any

__all__ = ["assemble_processor"]


def assemble_processor(cls: type, tokenizer: Any, image_processor: Any, **kwargs: Any) -> Any:
    """An instance of the processor class ``cls`` with a placeholder video processor.

    Works with and without torchvision: the argument class check of ``ProcessorMixin`` (which
    needs torchvision to find ``VideoProcessorMixin``) is bypassed for this instance only.
    ``kwargs`` go to ``cls.__init__`` (``chat_template``, InternVL's ``image_seq_length``, ...).
    """
    from transformers.video_processing_utils import BaseVideoProcessor  # transformers: heavy, imported on use

    processor = cls.__new__(cls)
    processor.check_argument_for_proper_class = lambda name, arg: None  # instance-local bypass
    try:
        cls.__init__(processor, image_processor=image_processor, tokenizer=tokenizer,
                     video_processor=BaseVideoProcessor(), **kwargs)
    finally:
        del processor.check_argument_for_proper_class
    return processor

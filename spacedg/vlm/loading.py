"""Load a local transformers VLM folder: ``(model, processor)``; the one no-torchvision workaround.

**Why a workaround.** transformers (checked with 5.23) constructs a Qwen-VL / InternVL processor
only when torchvision imports: ``ProcessorMixin.__init__`` checks the ``video_processor`` argument
against ``transformers.VideoProcessorMixin``, which is exported only with torchvision, so the
check dies with ``AttributeError: ... has no attribute '_extra_content'``, and
``AutoProcessor.from_pretrained`` fails the same way or with an ``ImportError`` (the video
processors need torchvision too). Where torchvision cannot be used (e.g. a CPU torch without a matching torchvision wheel),
:func:`~spacedg.vlm.processor.assemble_processor` builds the family's real processor class from the saved tokenizer, the
PIL image processor (``AutoImageProcessor.from_pretrained(path, backend="pil")``) and a
placeholder ``BaseVideoProcessor()``, skipping only that class check, for that one instance.
Images work exactly as with the stock processor; videos do not (nothing in spacedg uses them).
Where torchvision works, :func:`load_processor` takes the stock ``AutoProcessor`` path.

**Image pixel budget.** ``min_pixels`` / ``max_pixels`` are pixel counts per image (the
Qwen-VL convention). Qwen-VL image processors (``size`` has ``shortest_edge`` /
``longest_edge``) get ``size = {"shortest_edge": min_pixels, "longest_edge": max_pixels}``
(transformers v5 stores the pixel counts there). InternVL's processor (GotOCR2-style tiling, a
fixed tile of ``size["height"] × size["width"]`` pixels) has no pixel budget; its equivalent is
the tile count, so it gets ``min_patches = max(1, min_pixels // tile_area)`` and
``max_patches = max(1, max_pixels // tile_area)``. Use the same values for training and
inference.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path
from typing import Any

import torch

from spacedg.errors import InvalidDataError, ParameterError
from spacedg.vlm.processor import assemble_processor
from spacedg.vlm.tiny import build_tiny_vlm

__all__ = ["assemble_processor", "load_processor", "load_vlm", "pixel_budget", "resolve_dtype",  # assemble_processor: re-exported
           "set_pixel_budget"]


def set_pixel_budget(processor: Any, min_pixels: int | None = None, max_pixels: int | None = None) -> Any:
    """Set the per-image pixel budget of ``processor``'s image processor (see module doc); returns it."""
    if min_pixels is None and max_pixels is None:
        return processor
    for name, value in (("min_pixels", min_pixels), ("max_pixels", max_pixels)):
        if value is not None and (isinstance(value, bool) or not isinstance(value, int) or value < 1):
            raise ParameterError(f"{name} must be a positive pixel count, got {value!r}")
    if min_pixels is not None and max_pixels is not None and min_pixels > max_pixels:
        raise ParameterError(f"min_pixels ({min_pixels}) must be <= max_pixels ({max_pixels})")
    image_processor = processor.image_processor
    size = {k: v for k, v in dict(image_processor.size).items() if v is not None}
    if "shortest_edge" in size and "longest_edge" in size:  # Qwen-VL: pixel counts
        image_processor.size = {
            "shortest_edge": min_pixels if min_pixels is not None else size["shortest_edge"],
            "longest_edge": max_pixels if max_pixels is not None else size["longest_edge"],
        }
    elif hasattr(image_processor, "max_patches") and "height" in size:  # InternVL: tile counts
        tile = size["height"] * size["width"]
        if min_pixels is not None:
            image_processor.min_patches = max(1, min_pixels // tile)
        if max_pixels is not None:
            image_processor.max_patches = max(1, max_pixels // tile)
        image_processor.min_patches = min(image_processor.min_patches, image_processor.max_patches)
    else:
        raise ParameterError(f"{type(image_processor).__name__} has no pixel budget spacedg knows how to set; "
                             f"leave min_pixels / max_pixels unset for this model")
    return processor


def pixel_budget(processor: Any) -> dict[str, int | None]:
    """``{"min": pixels, "max": pixels}``: the per-image budget ``processor`` applies (the inverse of
    :func:`set_pixel_budget`; InternVL: its tile counts times the tile area; ``None`` where unknown)."""
    image_processor = getattr(processor, "image_processor", None)
    size = {k: v for k, v in dict(getattr(image_processor, "size", None) or {}).items() if v is not None}
    if "shortest_edge" in size and "longest_edge" in size:
        return {"min": int(size["shortest_edge"]), "max": int(size["longest_edge"])}
    if "height" in size and "width" in size and hasattr(image_processor, "max_patches"):
        tile = int(size["height"]) * int(size["width"])
        low = getattr(image_processor, "min_patches", None)
        return {"min": None if low is None else int(low) * tile, "max": int(image_processor.max_patches) * tile}
    return {"min": None, "max": None}


def _read_json(file: Path) -> dict[str, Any]:
    return json.loads(file.read_text()) if file.is_file() else {}


def _processor_class(folder: Path) -> type:
    """The processor class named in the folder's processor config, else the model type's."""
    import transformers
    from transformers import AutoConfig
    from transformers.models.auto.processing_auto import PROCESSOR_MAPPING_NAMES

    for name in ("processor_config.json", "preprocessor_config.json"):
        cls_name = _read_json(folder / name).get("processor_class")
        if cls_name and hasattr(transformers, cls_name):
            return getattr(transformers, cls_name)
    model_type = AutoConfig.from_pretrained(folder).model_type
    cls_name = PROCESSOR_MAPPING_NAMES.get(model_type)
    if not cls_name:
        raise InvalidDataError(f"{folder}: no processor class is known for model type {model_type!r}")
    return getattr(transformers, cls_name)


def _assemble_from_folder(folder: Path) -> Any:
    """The no-torchvision path of :func:`load_processor` (see module doc)."""
    import inspect

    from transformers import AutoImageProcessor, AutoTokenizer

    cls = _processor_class(folder)
    tokenizer = AutoTokenizer.from_pretrained(folder)
    image_processor = AutoImageProcessor.from_pretrained(folder, backend="pil")
    saved = _read_json(folder / "processor_config.json")
    params = set(inspect.signature(cls.__init__).parameters) - {"self", "image_processor", "tokenizer", "video_processor"}
    kwargs = {k: v for k, v in saved.items() if k in params}  # e.g. InternVL's image_seq_length
    template = saved.get("chat_template") or _read_json(folder / "chat_template.json").get("chat_template")
    if (folder / "chat_template.jinja").is_file():
        template = (folder / "chat_template.jinja").read_text()
    kwargs["chat_template"] = template or getattr(tokenizer, "chat_template", None)
    return assemble_processor(cls, tokenizer, image_processor, **kwargs)


def _check_folder(path: str | Path) -> Path:
    folder = Path(path)
    if not folder.is_dir():
        raise InvalidDataError(f"model folder {folder} does not exist; pass a local folder holding config.json, "
                               f"the weights and the processor files (e.g. downloaded with `hf download`)")
    if not (folder / "config.json").is_file():
        raise InvalidDataError(f"{folder} has no config.json, so it is not a transformers model folder; pass the "
                               f"folder that holds config.json, the weights and the processor files")
    return folder


def _adapter_base(folder: Path) -> Path | str | None:
    """For a folder holding a peft adapter (``adapter_config.json``, no ``config.json``): its base model folder.

    ``base_model_name_or_path`` is tried as given, then relative to the adapter folder. A base named
    ``tiny:<family>`` (a tiny model built in code, see :mod:`spacedg.vlm.tiny`) is returned as is.
    """
    if not folder.is_dir() or (folder / "config.json").is_file() or not (folder / "adapter_config.json").is_file():
        return None
    base = _read_json(folder / "adapter_config.json").get("base_model_name_or_path")
    if not base:
        raise InvalidDataError(f"{folder} holds a PEFT adapter but its adapter_config.json names no "
                               f"base_model_name_or_path; set it to the base model folder")
    if str(base).startswith("tiny:"):
        return str(base)
    for candidate in (Path(base), folder / base):
        if (candidate / "config.json").is_file():
            return candidate
    raise InvalidDataError(f"{folder} holds a PEFT adapter whose base model folder {base!r} (base_model_name_or_path "
                           f"in adapter_config.json) does not exist or has no config.json; put the base model there "
                           f"or edit base_model_name_or_path to point at it")


def _merge_adapter(model: Any, folder: Path) -> Any:
    """``model`` with the peft adapter saved in ``folder`` merged into its weights (a plain model again)."""
    try:
        from peft import PeftModel
    except ImportError as err:
        raise InvalidDataError(f"{folder} holds a PEFT adapter; loading it needs the peft package "
                               f"(pip install peft)") from err
    try:
        with warnings.catch_warnings():  # peft reads the deprecated `is_gradient_checkpointing` (transformers 5.23)
            warnings.filterwarnings("ignore", message=".*is_gradient_checkpointing.*", category=FutureWarning)
            return PeftModel.from_pretrained(model, folder).merge_and_unload()
    except (ValueError, KeyError, OSError, RuntimeError) as err:
        detail = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
        raise InvalidDataError(f"{folder}: cannot apply the PEFT adapter to its base model ({detail})") from err


def _has_processor(folder: Path) -> bool:
    return any((folder / name).is_file() for name in
               ("processor_config.json", "preprocessor_config.json", "tokenizer_config.json"))


def load_processor(path: str | Path, *, min_pixels: int | None = None, max_pixels: int | None = None) -> Any:
    """The processor saved in ``path``, with the pixel budget applied (see module doc).

    ``AutoProcessor.from_pretrained`` first; if that fails because torchvision is missing, the
    folder's processor class is assembled with :func:`assemble_processor`. The processor pads
    on the left (for batched generation).
    """
    from transformers import AutoProcessor
    from transformers.utils import is_torchvision_available

    folder = Path(path)
    if not folder.is_dir():
        raise InvalidDataError(f"processor folder {folder} does not exist; pass the model folder")
    try:
        processor = AutoProcessor.from_pretrained(folder)
    except Exception as err:
        if is_torchvision_available():
            raise InvalidDataError(f"{folder}: cannot load the processor ({type(err).__name__}: {err})") from err
        try:
            processor = _assemble_from_folder(folder)
        except InvalidDataError:
            raise
        except Exception as err2:
            raise InvalidDataError(f"{folder}: cannot load the processor without torchvision "
                                   f"({type(err2).__name__}: {err2}); check the tokenizer and "
                                   f"preprocessor files") from err2
    processor.tokenizer.padding_side = "left"
    return set_pixel_budget(processor, min_pixels, max_pixels)


def resolve_dtype(dtype: str | torch.dtype, device: str | torch.device) -> torch.dtype:
    """``"auto"``: bfloat16 on a CUDA device that supports it, else float32; names → torch dtypes."""
    if isinstance(dtype, torch.dtype):
        return dtype
    if dtype == "auto":
        dev = torch.device(device)
        cuda = dev.type == "cuda" and torch.cuda.is_available()
        return torch.bfloat16 if cuda and torch.cuda.is_bf16_supported() else torch.float32
    value = getattr(torch, str(dtype), None)
    if not isinstance(value, torch.dtype):
        raise ParameterError(f"unknown dtype {dtype!r}; use auto, float32, bfloat16 or float16")
    return value


def load_vlm(path: str | Path, *, device: str = "cpu", dtype: str | torch.dtype = "auto",
             min_pixels: int | None = None, max_pixels: int | None = None) -> tuple[Any, Any]:
    """``(model, processor)`` from a local folder: ``AutoModelForImageTextToText``, eval mode, on ``device``.

    A folder holding a peft adapter (``adapter_config.json`` and no ``config.json``) loads too: the
    base model from the folder named by ``base_model_name_or_path`` in ``adapter_config.json``,
    with the adapter merged into it; the processor from the adapter folder when it has one, else
    from the base folder. A base named ``tiny:<family>`` (what :func:`spacedg.sft.model.prepare_model`
    records for a tiny model built in code) is rebuilt with :func:`spacedg.vlm.build_tiny_vlm`.

    Raises :class:`~spacedg.errors.InvalidDataError` naming the path when the folder is missing,
    has no ``config.json`` or holds a model that is not an image-text-to-text model (or, for an
    adapter, when its base folder is missing).
    """
    from transformers import AutoModelForImageTextToText

    adapter = Path(path)
    base = _adapter_base(adapter)
    torch_dtype = resolve_dtype(dtype, device)
    if isinstance(base, str):  # an adapter trained on a tiny model built in code (seed 0)
        model, processor = build_tiny_vlm(base[len("tiny:"):])
        model = _merge_adapter(model.to(torch_dtype), adapter)
        if _has_processor(adapter):
            processor = load_processor(adapter, min_pixels=min_pixels, max_pixels=max_pixels)
        else:
            processor.tokenizer.padding_side = "left"
            set_pixel_budget(processor, min_pixels, max_pixels)
        return model.to(device).eval(), processor
    folder = _check_folder(path) if base is None else base
    try:
        model = AutoModelForImageTextToText.from_pretrained(folder, dtype=torch_dtype)
    except (ValueError, KeyError, OSError) as err:
        detail = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
        raise InvalidDataError(f"{folder}: cannot load an image-text-to-text model ({detail}); "
                               f"pass a transformers VLM folder (Qwen2-VL, Qwen2.5-VL, Qwen3-VL, InternVL, ...)") from err
    if base is not None:
        model = _merge_adapter(model, adapter)
        folder = adapter if _has_processor(adapter) else base
    processor = load_processor(folder, min_pixels=min_pixels, max_pixels=max_pixels)
    return model.to(device).eval(), processor

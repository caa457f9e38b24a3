"""The model side of supervised fine-tuning: build/load a VLM, freeze parts, LoRA, checkpointing, save.

A VLM is split into three **groups** of parameters (:func:`module_groups`), found from the
module structure shared by the transformers 5 classes of Qwen2-VL, Qwen2.5-VL, Qwen3-VL and
InternVL:

* ``"vision"``: the vision tower (``model.visual`` / ``model.vision_tower``) without its merger;
* ``"merger"``: what projects vision features into the language model: Qwen's
  ``model.visual.merger`` (and Qwen3-VL's ``model.visual.deepstack_merger_list``), InternVL's
  ``model.multi_modal_projector``;
* ``"language"``: the language model (``model.language_model``, embeddings included) and ``lm_head``.

Every parameter is in exactly one group; an architecture with parameters outside all three is
refused with a :class:`~spacedg.errors.ParameterError` naming them.

**Freezing** uses ``requires_grad_()`` on each group's parameters (setting ``requires_grad`` on a
*module* attribute freezes nothing). Defaults (``conf/model/base.yaml``): vision frozen; merger and
language model trained in full fine-tuning; with LoRA only the adapters train
(``freeze_merger: auto`` resolves to frozen under LoRA and trained otherwise).

**Storage dtypes** (:func:`storage_dtypes`). ``dtype: auto`` keeps every *trained* weight in
float32 (the master weights: at lr 1e-5, bf16 weights round most updates away) and lets the
launch's mixed precision (``train.bf16``) compute in bf16. *Frozen* weights are stored in the
mixed-precision dtype (bf16) where every rank holds them whole (one process, DDP: the frozen base
of a LoRA run is half the size) and in float32 where the launch shards them (FSDP, ZeRO-3: a shard
costs 1/N, and FSDP2 needs uniform dtypes in a unit). The model is loaded in the frozen dtype
(the published bf16 weights load losslessly) and its trained parameters are then upcast. An
explicit ``dtype`` stores everything in it (``bfloat16``: pure bf16 training, no master weights).

**LoRA** (``lora=True``) adds adapters to the language model only: the default target regex matches
the attention and MLP projections of its decoder layers (``q/k/v/o_proj``, ``gate/up/down_proj``),
built from the language model's module name, e.g.
``model\\.language_model\\.layers\\.\\d+\\.(?:self_attn|mlp)\\.(?:q_proj|...)``. (``"all-linear"``
would also wrap the vision tower and merger: InternVL's vision tower even has ``q_proj`` /
``k_proj`` / ``v_proj`` modules of its own, so an unanchored name list would too.) A custom
``lora_target`` must match at least one module of the language model and nothing outside it.
With LoRA the base weights of the language model are always frozen (whatever ``freeze_language``
says), and so, by default, are the vision tower and the merger; a group explicitly unfrozen
(``freeze_merger=false``, ``freeze_vision=false``) is trained in full as peft ``modules_to_save``: peft keeps the original
module frozen and trains a copy, so the copy's weights are saved in the adapter checkpoint next to
``lora_A`` / ``lora_B`` (a module that merely had ``requires_grad`` would silently be missing from
the adapter files). Trainable parameters of a LoRA model are therefore exactly the ``lora_``
parameters, plus the ``modules_to_save`` copies of the groups asked for.

**Gradient checkpointing** is non-reentrant. transformers 5.23 renamed the API:
``activation_checkpointing_enable(activation_checkpointing_kwargs=...)``
(``gradient_checkpointing_enable`` is a deprecated alias that warns); the older name is used only
where the new one does not exist. With frozen input embeddings ``enable_input_require_grads()``
makes the embedding output require grad. ``use_cache`` is switched off in the config(s) of every
training model (FSDP's activation checkpointing recomputes layers too). That
transformers call (and peft's) also hooks the vision tower's patch embedding; on a frozen vision
tower the hook is removed again, so autograd never records the frozen tower.

:func:`prepare_model` returns the model in train mode. :func:`save_for_inference` writes a folder
that :func:`spacedg.vlm.load_vlm` loads as a plain model (LoRA merged on a copy);
:func:`rebuild_with_state` rebuilds the training model on the CPU from gathered weights (the
``final/`` export of sharded launches, see :mod:`spacedg.sft.distributed`).
"""

from __future__ import annotations

import copy
import json
import re
import sys
import warnings
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import huggingface_hub
import torch

from spacedg.errors import ParameterError
from spacedg.vlm.loading import load_vlm, resolve_dtype, set_pixel_budget
from spacedg.vlm.tiny import TINY_FAMILIES, build_tiny_vlm

__all__ = ["GROUPS", "ModelOptions", "default_lora_target", "drop_vision_input_grad_hooks", "module_groups", "prepare_model",
           "HALF_DTYPES", "rebuild_with_state", "save_for_inference", "storage_dtypes", "trainable_summary"]

#: The parameter groups of a VLM, in model order.
GROUPS = ("vision", "merger", "language")

_VISION_NAMES = ("visual", "vision_tower", "vision_model")
_PROJECTOR_NAMES = ("multi_modal_projector", "mm_projector")
_LORA_PROJECTIONS = ("q_proj", "k_proj", "v_proj", "o_proj", "gate_proj", "up_proj", "down_proj")
_TINY_PREFIX = "tiny:"


@dataclass
class ModelOptions:
    """What to load and what to train (see the module doc).

    Every field is required: the defaults live once, in ``conf/model/base.yaml`` (which the other
    model configs extend); the app builds this class from the ``model`` group with
    ``hydra.utils.instantiate``.

    ``path``: a local model folder, or ``"tiny:<family>"`` for a tiny model built in code
    (:func:`spacedg.vlm.build_tiny_vlm`); a path that is no folder but looks like a hub id
    (``Qwen/Qwen2.5-VL-7B-Instruct``) is fetched with ``huggingface_hub.snapshot_download`` first. ``dtype``: ``"auto"`` (bfloat16 on a CUDA device that
    supports it, else float32), ``"float32"``, ``"bfloat16"`` or ``"float16"``. ``lora_target``: a
    regex ``re.fullmatch``-ed against module names (peft's rule for a string ``target_modules``);
    ``None`` = the language model's attention and MLP projections. ``min_pixels`` / ``max_pixels``:
    the per-image pixel budget of the processor (:func:`spacedg.vlm.loading.set_pixel_budget`).
    """

    path: str
    dtype: str
    freeze_vision: bool
    freeze_merger: bool | str
    freeze_language: bool
    lora: bool
    lora_r: int
    lora_alpha: int
    lora_dropout: float
    lora_target: str | None
    gradient_checkpointing: bool
    min_pixels: int | None
    max_pixels: int | None

    def __post_init__(self) -> None:
        self.validate()

    @property
    def merger_frozen(self) -> bool:
        """``freeze_merger`` resolved: ``"auto"`` is frozen with LoRA and trained without."""
        return self.lora if self.freeze_merger == "auto" else bool(self.freeze_merger)

    @property
    def tiny_family(self) -> str | None:
        """``<family>`` of a ``tiny:<family>`` path, else ``None``."""
        path = str(self.path)
        return path[len(_TINY_PREFIX):] if path.startswith(_TINY_PREFIX) else None

    def validate(self) -> None:
        """Raise :class:`~spacedg.errors.ParameterError` for an impossible or ill-typed setting."""
        if not isinstance(self.path, (str, Path)) or not str(self.path).strip():
            raise ParameterError("model path is empty; give a local model folder or 'tiny:<family>'")
        path = str(self.path)
        if self.tiny_family is not None and self.tiny_family not in TINY_FAMILIES:
            raise ParameterError(f"unknown tiny model {path!r}; use tiny:<family> with family one of "
                                 f"{', '.join(TINY_FAMILIES)}")
        resolve_dtype(self.dtype, "cpu")  # raises ParameterError for an unknown name
        for name in ("freeze_vision", "freeze_language", "lora", "gradient_checkpointing"):
            if not isinstance(getattr(self, name), bool):
                raise ParameterError(f"{name} must be true or false, got {getattr(self, name)!r}")
        if not isinstance(self.freeze_merger, bool) and self.freeze_merger != "auto":
            raise ParameterError(f"freeze_merger must be true, false or auto, got {self.freeze_merger!r}")
        if not self.lora and self.freeze_vision and self.merger_frozen and self.freeze_language:
            raise ParameterError("nothing to train: freeze_vision, freeze_merger and freeze_language are all true "
                                 "and lora is false; unfreeze a part or set lora=true")
        if self.lora:
            if isinstance(self.lora_r, bool) or not isinstance(self.lora_r, int) or self.lora_r < 1:
                raise ParameterError(f"lora_r must be an integer >= 1, got {self.lora_r!r}")
            if isinstance(self.lora_alpha, bool) or not isinstance(self.lora_alpha, (int, float)) or self.lora_alpha <= 0:
                raise ParameterError(f"lora_alpha must be > 0, got {self.lora_alpha!r}")
            if isinstance(self.lora_dropout, bool) or not isinstance(self.lora_dropout, (int, float)) \
                    or not 0 <= self.lora_dropout < 1:
                raise ParameterError(f"lora_dropout must be in [0, 1), got {self.lora_dropout!r}")
        elif self.lora_target is not None:
            raise ParameterError(f"lora_target is set ({self.lora_target!r}) but lora is false; set lora=true or "
                                 f"drop lora_target")
        if self.lora_target is not None:
            if not isinstance(self.lora_target, str) or not self.lora_target:
                raise ParameterError(f"lora_target must be a non-empty regex string, got {self.lora_target!r}")
            try:
                re.compile(self.lora_target)
            except re.error as err:
                raise ParameterError(f"lora_target {self.lora_target!r} is not a valid regex: {err}") from err
        for name in ("min_pixels", "max_pixels"):
            value = getattr(self, name)
            if value is not None and (isinstance(value, bool) or not isinstance(value, int) or value < 1):
                raise ParameterError(f"{name} must be a positive pixel count, got {value!r}")
        if self.min_pixels is not None and self.max_pixels is not None and self.min_pixels > self.max_pixels:
            raise ParameterError(f"min_pixels ({self.min_pixels}) must be <= max_pixels ({self.max_pixels})")


# ----------------------------------------------------------------------------------------------
# groups


def _last(name: str) -> str:
    return name.rsplit(".", 1)[-1]


def _under(name: str, prefix: str) -> bool:
    return name == prefix or name.startswith(prefix + ".")


def module_groups(model: torch.nn.Module) -> dict[str, list[str]]:
    """Name prefixes of the ``"vision"``, ``"merger"`` and ``"language"`` parameters of ``model``.

    A parameter named ``n`` is in a group when ``n == p`` or ``n`` starts with ``p + "."`` for one
    of its prefixes ``p``. Works on the plain model and on a peft-wrapped one (names then start with
    ``base_model.model.``). Raises :class:`~spacedg.errors.ParameterError` when the model has no
    language model or has parameters outside the three groups.
    """
    modules = dict(model.named_modules())
    language = next((n for n in modules if _last(n) == "language_model"), None)
    if language is None:
        raise ParameterError(f"{type(model).__name__} has no 'language_model' module; spacedg knows the module "
                             f"layout of Qwen2-VL, Qwen2.5-VL, Qwen3-VL and InternVL")
    vision = next((n for n in modules if _last(n) in _VISION_NAMES), None)
    groups: dict[str, list[str]] = {"vision": [], "merger": [], "language": [language]}
    groups["language"] += [n for n in modules if _last(n) == "lm_head" and not _under(n, language)]
    groups["merger"] += [n for n in modules if _last(n) in _PROJECTOR_NAMES
                         and not (vision and _under(n, vision)) and not _under(n, language)]
    if vision is not None:
        for child, sub in modules[vision].named_children():
            if any(True for _ in sub.parameters()):  # parameter-free children (rotary tables) are in no group
                groups["merger" if "merger" in child else "vision"].append(f"{vision}.{child}")
        groups["vision"] += [f"{vision}.{p}" for p, _ in modules[vision].named_parameters(recurse=False)]
    outside = [n for n, _ in model.named_parameters()
               if not any(_under(n, p) for prefixes in groups.values() for p in prefixes)]
    if outside:
        raise ParameterError(f"{type(model).__name__}: {len(outside)} parameters are outside the vision tower, "
                             f"merger and language model (first: {', '.join(outside[:3])}); spacedg does not know "
                             f"how to group this architecture")
    return groups


def _group_of(name: str, groups: dict[str, list[str]]) -> str:
    for group, prefixes in groups.items():
        if any(_under(name, p) for p in prefixes):
            return group
    raise ParameterError(f"parameter {name} is in no group")  # module_groups guarantees it is not reached


def trainable_summary(model: torch.nn.Module) -> dict[str, dict[str, int]]:
    """``{group: {"trainable": n, "total": n}}`` for the three groups and ``"all"`` (parameter counts).

    For a LoRA model the adapters count in ``"language"`` and the ``modules_to_save`` copies in
    their group (the frozen originals stay in ``"total"``).
    """
    groups = module_groups(model)
    summary = {g: {"trainable": 0, "total": 0} for g in (*GROUPS, "all")}
    for name, param in model.named_parameters():
        for key in (_group_of(name, groups), "all"):
            summary[key]["total"] += param.numel()
            summary[key]["trainable"] += param.numel() if param.requires_grad else 0
    return summary


# ----------------------------------------------------------------------------------------------
# preparation


def default_lora_target(model: torch.nn.Module) -> str:
    """The default LoRA regex: the attention and MLP projections of the language model's decoder layers."""
    language = module_groups(model)["language"][0]
    return rf"{re.escape(language)}\.(?:.*\.)?layers\.\d+\.(?:self_attn|mlp)\.(?:{'|'.join(_LORA_PROJECTIONS)})"


def _lora_targets(model: torch.nn.Module, regex: str) -> list[str]:
    """The module names ``regex`` selects (peft's ``re.fullmatch`` rule), checked to be in the language model."""
    groups = module_groups(model)
    modules = dict(model.named_modules())
    matched = [n for n in modules if n and re.fullmatch(regex, n)]
    outside = [n for n in matched if not any(_under(n, p) for p in groups["language"])]
    if outside:
        raise ParameterError(f"lora_target {regex!r} matches {len(outside)} modules outside the language model "
                             f"(first: {', '.join(outside[:3])}); LoRA is applied to the language model only, "
                             f"anchor the regex on {groups['language'][0]!r}")
    linear = [n for n in matched if isinstance(modules[n], torch.nn.Linear)]
    if not linear:
        raise ParameterError(f"lora_target {regex!r} matches no linear layer of the language model "
                             f"(it is matched with re.fullmatch against names like "
                             f"'{groups['language'][0]}.layers.0.self_attn.q_proj')")
    return matched


def _wrappable(model: torch.nn.Module, prefixes: list[str]) -> list[str]:
    """``prefixes`` as module names peft can wrap in ``modules_to_save`` (ModuleLists expanded)."""
    modules = dict(model.named_modules())
    out: list[str] = []
    for prefix in prefixes:
        module = modules.get(prefix)
        if module is None:  # a parameter attached directly to the vision tower
            raise ParameterError(f"{prefix} is a bare parameter, which LoRA training cannot save as "
                                 f"modules_to_save; keep that part frozen")
        if isinstance(module, (torch.nn.ModuleList, torch.nn.ModuleDict)):
            out += _wrappable(model, [f"{prefix}.{child}" for child, _ in module.named_children()])
        else:
            out.append(prefix)
    return out


def _text_configs(model: torch.nn.Module) -> list[Any]:
    """The model's config and its text sub-config (where ``use_cache`` is read), without duplicates."""
    config = getattr(model, "config", None)
    if config is None:
        return []
    configs = [config]
    text = config.get_text_config() if hasattr(config, "get_text_config") else config
    if text is not config:
        configs.append(text)
    return configs


def _set_use_cache(model: torch.nn.Module, value: bool) -> None:
    for cfg in _text_configs(model):
        cfg.use_cache = value


def _enable_checkpointing(model: Any) -> None:
    kwargs = {"use_reentrant": False}
    if hasattr(model, "activation_checkpointing_enable"):  # transformers >= 5.23
        model.activation_checkpointing_enable(activation_checkpointing_kwargs=kwargs)
    else:
        model.gradient_checkpointing_enable(gradient_checkpointing_kwargs=kwargs)
    embeddings = model.get_input_embeddings()
    if not any(p.requires_grad for p in embeddings.parameters()) and not getattr(model, "_require_grads_hooks", None):
        model.enable_input_require_grads()
    _set_use_cache(model, False)


def drop_vision_input_grad_hooks(model: torch.nn.Module) -> int:
    """On a frozen vision tower, remove the ``enable_input_require_grads`` hooks; returns how many.

    transformers' ``enable_input_require_grads()`` hooks the input embeddings of *every* sub-model
    with ``get_input_embeddings`` -- for Qwen2-VL / Qwen2.5-VL / InternVL also the vision tower's
    patch embedding -- and both ``activation_checkpointing_enable()`` and peft's
    ``get_peft_model`` call it. On a frozen vision tower that hook only makes autograd record (and,
    with checkpointing, recompute) the whole tower for nothing. :func:`prepare_model` calls this;
    call it again after anything that re-enables checkpointing (e.g. ``TrainingArguments``'
    ``activation_checkpointing=True``). Does nothing while any vision parameter is trainable.
    """
    groups = module_groups(model)
    vision = [(n, m) for n, m in model.named_modules() if any(_under(n, p) for p in groups["vision"])]
    if any(p.requires_grad for _, m in vision for p in m.parameters(recurse=False)):
        return 0
    removed = 0
    for _, module in vision:
        for key, hook in list(module._forward_hooks.items()):
            if getattr(hook, "__name__", "").startswith("make_inputs_require_grad"):
                del module._forward_hooks[key]
                removed += 1
    return removed


#: The storage / compute dtype of each mixed precision setting.
HALF_DTYPES = {"bf16": torch.bfloat16, "fp16": torch.float16}


def storage_dtypes(dtype: str, mixed_precision: str = "no", shards_parameters: bool = False) -> tuple[torch.dtype, torch.dtype]:
    """``(trained, frozen)``: the dtypes the trained and the frozen weights are stored in.

    ``dtype`` is the ``model.dtype`` option; ``mixed_precision`` the launch's (``"bf16"``,
    ``"fp16"`` or ``"no"``); ``shards_parameters`` whether the launch shards the weights (FSDP,
    ZeRO-3). ``"auto"``: trained float32 (master weights); frozen in the mixed-precision dtype
    unless the launch shards them (then float32). Any other value: that dtype for both.
    """
    if dtype != "auto":
        value = resolve_dtype(dtype, "cpu")
        return value, value
    half = HALF_DTYPES.get(mixed_precision)
    return torch.float32, half if half is not None and not shards_parameters else torch.float32


def _empty(folder: str, dtype: torch.dtype, options: ModelOptions) -> tuple[Any, Any]:
    """The model of ``folder`` without its weights (parameters on the meta device, buffers real) and
    its processor: what FSDP ranks other than the first need when rank 0 broadcasts the weights."""
    from accelerate import init_empty_weights
    from transformers import AutoConfig, AutoModelForImageTextToText

    from spacedg.vlm import load_processor

    config = AutoConfig.from_pretrained(folder)
    with init_empty_weights():  # include_buffers=False: rotary tables and other buffers are computed for real
        model = AutoModelForImageTextToText.from_config(config, dtype=dtype)
    return model, load_processor(folder, min_pixels=options.min_pixels, max_pixels=options.max_pixels)


def _unread(model: torch.nn.Module) -> None:
    """Give every meta-device parameter uninitialised CPU storage (``torch.empty``: pages the OS commits
    only when written, i.e. when FSDP fills this rank's shards), as accelerate's FSDP preparation
    expects of the ranks that do not read the weights; tied parameters stay tied."""
    made: dict[int, torch.nn.Parameter] = {}
    for module in model.modules():
        for name, param in list(module.named_parameters(recurse=False)):
            if param.device.type != "meta":
                continue
            if id(param) not in made:
                made[id(param)] = torch.nn.Parameter(torch.empty(param.shape, dtype=param.dtype, device="cpu"),
                                                     requires_grad=param.requires_grad)
            module._parameters[name] = made[id(param)]


def _build(options: ModelOptions, device: str, dtype: torch.dtype, empty: bool = False) -> tuple[Any, Any]:
    path = str(options.path)
    if empty and options.tiny_family is None:
        return _empty(_local_folder(path), dtype, options)
    if options.tiny_family is not None:
        model, processor = build_tiny_vlm(options.tiny_family)
        model.name_or_path = path  # recorded as base_model_name_or_path in LoRA adapter configs
        model = model.to(device=device, dtype=dtype)
        return model, set_pixel_budget(processor, options.min_pixels, options.max_pixels)
    return load_vlm(_local_folder(path), device=device, dtype=dtype, min_pixels=options.min_pixels,
                    max_pixels=options.max_pixels)


_HUB_ID = re.compile(r"[A-Za-z0-9][\w.-]*/[\w.-]+")


def _local_folder(path: str) -> str:
    """``path`` itself when it is a folder (or not hub-id shaped); else the hub snapshot folder of ``owner/name``.

    The download goes through ``huggingface_hub.snapshot_download`` (its cache; ``HF_HUB_OFFLINE=1``
    uses the cache only). A failure names both readings of ``path``.
    """
    if Path(path).exists() or not _HUB_ID.fullmatch(path):
        return path
    try:
        return huggingface_hub.snapshot_download(path)
    except Exception as err:  # network, auth, missing repo: one message
        detail = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
        raise ParameterError(f"model path {path!r} is not a local folder and could not be fetched as a hub model "
                             f"({type(err).__name__}: {detail}); download it first (hf download {path} --local-dir "
                             f"DIR) and pass DIR") from err


def _apply_lora(model: Any, options: ModelOptions, groups: dict[str, list[str]]) -> Any:
    try:
        from peft import LoraConfig, get_peft_model  # peft takes seconds to import; only LoRA runs need it
    except ImportError as err:
        raise ParameterError("lora=true needs the peft package (pip install peft)") from err
    regex = options.lora_target or default_lora_target(model)
    _lora_targets(model, regex)
    to_save = []
    if not options.merger_frozen:
        to_save += _wrappable(model, groups["merger"])
    if not options.freeze_vision:
        to_save += _wrappable(model, groups["vision"])
    config = LoraConfig(r=options.lora_r, lora_alpha=options.lora_alpha, lora_dropout=float(options.lora_dropout),
                        target_modules=regex, modules_to_save=to_save or None, bias="none", task_type="CAUSAL_LM")
    with warnings.catch_warnings():  # peft reads the deprecated `is_gradient_checkpointing` (transformers 5.23)
        warnings.filterwarnings("ignore", message=".*is_gradient_checkpointing.*", category=FutureWarning)
        return get_peft_model(model, config)


def prepare_model(options: ModelOptions, *, device: str = "cpu", mixed_precision: str = "no",
                  shards_parameters: bool = False, empty_weights: bool = False) -> tuple[Any, Any]:
    """``(model, processor)`` ready for training as ``options`` says (see the module doc).

    The model is a transformers model, or a peft ``PeftModelForCausalLM`` with ``lora=True``, in
    train mode on ``device``; its weights are stored as :func:`storage_dtypes` says for the
    launch's ``mixed_precision`` and ``shards_parameters``. ``empty_weights``: the weights are not
    read (uninitialised storage; FSDP's ``cpu_ram_efficient_loading`` fills this rank's shards from
    rank 0). The processor has the pixel budget applied.
    """
    options.validate()
    trained, frozen_dtype = storage_dtypes(options.dtype, mixed_precision, shards_parameters)
    model, processor = _build(options, device, frozen_dtype, empty_weights)
    groups = module_groups(model)
    frozen = {"vision": options.freeze_vision, "merger": options.merger_frozen,
              "language": options.freeze_language or options.lora}
    for name, param in model.named_parameters():
        param.requires_grad_(not frozen[_group_of(name, groups)])
    if options.gradient_checkpointing:
        _enable_checkpointing(model)
    if options.lora:
        model = _apply_lora(model, options, groups)
    for param in model.parameters():
        if param.requires_grad and param.dtype != trained:
            param.data = param.data.to(trained)
    if empty_weights:
        _unread(model)
    # training needs no KV cache; with activation checkpointing (the model's or FSDP's) a cache would
    # grow again in each recomputation
    _set_use_cache(model, False)
    drop_vision_input_grad_hooks(model)
    return model.train(), processor


def rebuild_with_state(options: ModelOptions, state: dict[str, torch.Tensor]) -> Any:
    """The training model of ``options`` rebuilt on the CPU (float32) with ``state`` loaded strictly.

    ``state`` holds every weight under the training model's own names (a gathered FSDP / ZeRO-3
    state dict). Used by rank 0 to write ``final/`` of a sharded run; costs about two models'
    memory on the host while it runs.
    """
    plain = replace(options, dtype="float32", gradient_checkpointing=False)
    model, _ = prepare_model(plain)
    model.load_state_dict(state, strict=True)  # copied (and cast) into the float32 model
    return model.eval()


# ----------------------------------------------------------------------------------------------
# saving


def _is_peft(model: Any) -> bool:
    peft = sys.modules.get("peft")  # a PeftModel exists only once peft was imported: no import needed here
    return peft is not None and isinstance(model, peft.PeftModel)


def _cast(state: dict[str, torch.Tensor], dtype: torch.dtype | None) -> dict[str, torch.Tensor]:
    if dtype is None:
        return state
    return {k: v.to(dtype) if v.is_floating_point() else v for k, v in state.items()}


def save_for_inference(model: Any, processor: Any, out_dir: str | Path, *, save_dtype: torch.dtype | None = None,
                       in_place: bool = False) -> Path:
    """Write ``model`` (LoRA merged) and ``processor`` to ``out_dir`` for :func:`spacedg.vlm.load_vlm`.

    A peft model is merged on a deep copy (the training model keeps its unmerged adapters; the
    copy costs one model's memory on its device for the duration of the call), or in place with
    ``in_place=True`` (for a model built only to be saved). ``save_dtype`` (e.g. bfloat16 after mixed
    precision training) casts the saved weights: the model itself only when it is ours (``in_place``,
    or the merged copy), else a cast copy of its weights. The saved config has ``use_cache`` on again
    and names the saved dtype. The processor is saved alongside, pixel budget included.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if _is_peft(model):
        model = (model if in_place else copy.deepcopy(model)).merge_and_unload()
        in_place = True  # the merged copy is ours
    if in_place and save_dtype is not None:
        model = model.to(save_dtype)
    configs = _text_configs(model)
    before = [getattr(cfg, "use_cache", None) for cfg in configs]
    _set_use_cache(model, True)
    try:
        # a model that is not ours is saved through a cast copy of its weights
        state = _cast(model.state_dict(), save_dtype) if save_dtype is not None and not in_place else None
        model.save_pretrained(out, state_dict=state)
    finally:
        for cfg, use_cache in zip(configs, before):
            cfg.use_cache = use_cache
    if state is not None:  # save_pretrained wrote the model's own dtype into config.json
        file = out / "config.json"
        config = json.loads(file.read_text())
        name = str(save_dtype).split(".")[-1]
        for node in [config, *(v for v in config.values() if isinstance(v, dict) and "dtype" in v)]:
            if "dtype" in node:
                node["dtype"] = name
        file.write_text(json.dumps(config, indent=2, sort_keys=True) + "\n")
    processor.save_pretrained(out)
    return out

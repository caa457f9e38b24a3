"""The paper's prompt variants, as chat conversations for ``processor.apply_chat_template``.

Variants (``--variant`` of ``spacedg predict``):

``default``
    System :data:`~spacedg.data.chat.ANSWER_PROMPT` (answer only, in ``<answer>`` tags); user
    turn = one ``{"type": "image"}`` per view, then the question with its option lines.
``no_image``
    The paper's non-image baseline: the same conversation without the images. The question
    still says "image A"; that is the point (a blind model's language prior).
``degradation_info``
    The paper's Table 2: for a degraded item, the user text starts with the degradation type and
    its severity as the rendering parameter ranges of the preset the bench was rendered with
    (:func:`degradation_info`). Clean items get no extra text (there is nothing to tell).
``cot``
    The paper's two-stage degradation-first reasoning: stage 1 asks the model to name the
    degradation from the list of known ones with a short description
    (:data:`COT_STAGE1_PROMPT`); stage 2 continues the same conversation with the question and
    asks for step-by-step reasoning ending in the tagged answer (:data:`COT_STAGE2_SUFFIX`).
    :func:`parse_degradation_guess` reads the stage-1 answer, so the report can give the paper's
    degradation-recognition accuracy.

The paper shows its two templates only as figures; the wording here is ours and is recorded
in every prediction file's sidecar, so a result always states the exact prompt it came from.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from typing import Any

from spacedg.data.chain import Chain
from spacedg.data.chat import ANSWER_FORMATS, ANSWER_PROMPT, chat_messages
from spacedg.errors import UnknownPluginError
from spacedg.eval.bench import CLEAN, BenchRow
from spacedg.plugins.registry import degradation_names, get_degradation
from spacedg.plugins.specs import REFERENCE_DEPTH_M, REFERENCE_IMAGE_SIZE

__all__ = [
    "COT_STAGE1_PROMPT",
    "COT_STAGE2_SUFFIX",
    "COT_SYSTEM_PROMPT",
    "VARIANTS",
    "chat_messages",
    "conversation",
    "cot_followup",
    "degradation_info",
    "known_degradations",
    "parse_degradation_guess",
    "prompt_texts",
]

#: Prompt variants, in the order the report lists them.
VARIANTS: tuple[str, ...] = ("default", "no_image", "degradation_info", "cot")

#: System text of the ``cot`` variant: reasoning allowed, the answer still tagged.
COT_SYSTEM_PROMPT: str = (
    "Answer the question about the image(s). You may reason first; end with the final answer "
    "wrapped in <answer></answer> tags: " + ANSWER_FORMATS
)
#: Stage 1 of ``cot``: ``{choices}`` is replaced by the known degradation names.
COT_STAGE1_PROMPT: str = (
    "Before the question, look at the image quality. Which visual degradation affects these "
    "images? Choose exactly one of: {choices}. Reply in the form "
    "'Degradation: <name>. Description: <one short sentence on what you see>'."
)
#: Appended to the question in stage 2 of ``cot``.
COT_STAGE2_SUFFIX: str = (
    "\nTaking the degradation you identified into account, reason step by step about the "
    "spatial question, then give the final answer wrapped in <answer></answer> tags."
)

#: Words a model may use for a degradation (lower case) → its name.
_ALIASES: dict[str, str] = {
    "clean": CLEAN, "none": CLEAN, "no degradation": CLEAN,
    "out of focus": "defocus", "out-of-focus": "defocus", "defocus blur": "defocus",
    "lens distortion": "distortion", "fisheye": "distortion", "fish-eye": "distortion",
    "fog": "haze", "mist": "haze",
    "jpeg": "jpeg_compression", "jpeg compression": "jpeg_compression", "compression artifacts": "jpeg_compression",
    "low light": "low_light", "low-light": "low_light", "underexposure": "low_light", "under-exposure": "low_light",
    "low resolution": "low_res", "low-resolution": "low_res", "low res": "low_res", "low-res": "low_res", "pixelation": "low_res",
    "motion blur": "motion_blur", "motion-blur": "motion_blur",
    "over exposure": "over_exposure", "over-exposure": "over_exposure", "overexposure": "over_exposure", "overexposed": "over_exposure",
    "water droplets": "water_droplets", "water-droplets": "water_droplets", "raindrops": "water_droplets", "rain drops": "water_droplets",
}


def known_degradations() -> list[str]:
    """Names of the loaded degradation plugins (sorted), the choices of ``cot`` stage 1."""

    return degradation_names()  # names only: a clash between two plugins is not an error here


def _number(value: float) -> str:
    return f"{value:.4g}"


#: Units written after a range in the preamble (dimensionless and linear-light values go bare).
_SHOWN_UNITS = frozenset({"m", "px", "rad", "deg"})


def _ranges_text(name: str, preset: str, scene_depth: float | None = None, provenance: bool = True) -> str:
    """``"param in [low, high] unit, …"`` of ``preset``: the ranges the bench was rendered from.

    Depth-relative ranges (``ParamRange(per_depth=True)``: metres stated at
    :data:`~spacedg.plugins.specs.REFERENCE_DEPTH_M`) are given as resolved for the sample:
    scaled by ``scene_depth / REFERENCE_DEPTH_M`` and clamped to the hard limits exactly as
    :meth:`~spacedg.plugins.specs.DegradationSpec.sample_params` does, followed by the reference
    numbers. ``scene_depth=None`` with ``provenance``: the row was resolved at the reference (its
    ranges are the written ones); without ``provenance`` (a foreign bench) the scene depth is not
    known, and the text says the ranges hold at the reference depth and scale with the scene's.
    """

    try:
        spec = get_degradation(name)
    except UnknownPluginError:
        return ""
    if preset not in spec.presets:
        return ""
    units = {p.name: p for p in spec.params}
    parts = []
    for param, span in spec.presets[preset].items():
        info = units.get(param)
        unit = f" {info.unit}" if info is not None and info.unit in _SHOWN_UNITS else ""

        def bounds(low: float, high: float) -> str:
            return f"= {_number(low)}{unit}" if low == high else f"in [{_number(low)}, {_number(high)}]{unit}"

        text = f"{param} {bounds(span.low, span.high)}"
        if span.per_depth and scene_depth is not None:
            low, high = (span.scaled(v, scene_depth) for v in (span.low, span.high))
            if info is not None:
                low, high = (v if info.low is None else max(v, float(info.low)) for v in (low, high))
                low, high = (v if info.high is None else min(v, float(info.high)) for v in (low, high))
            written = f"{_number(span.low)}{unit}" if span.fixed else f"[{_number(span.low)}, {_number(span.high)}]{unit}"
            text = (f"{param} {bounds(low, high)} (scaled to the scene depth of {_number(float(scene_depth))} m; "
                    f"{written} at {_number(REFERENCE_DEPTH_M)} m)")
        elif span.per_depth and not provenance:
            text += f" at a scene depth of {_number(REFERENCE_DEPTH_M)} m, scaled with the scene's depth"
        if span.per_size:  # pixels stated at the reference frame (the provenance holds the pixels used)
            text += f" at a {REFERENCE_IMAGE_SIZE[0]}×{REFERENCE_IMAGE_SIZE[1]} image, scaled with its size"
        parts.append(text)
    return ", ".join(parts)


def degradation_info(row: BenchRow) -> str:
    """The ``degradation_info`` preamble of a row (empty for clean rows).

    Each degradation of the row's chain is named with its preset's parameter ranges, e.g.
    ``"The images are degraded by haze (severity given as the rendering parameter ranges:
    density in [3.5, 6], airlight in [0.7, 0.9], depth_ref = 15 m (scaled to the scene depth of
    3 m; 12.5 m at 2.5 m))."``. The chain, presets and scene depth (``scene_depth_m``) come from the
    row's ``degradation`` provenance: metres of scale-aware presets (defocus ``depth``, motion
    ``trans``, haze ``depth_ref``) are the ranges resolved at that depth, as rendered. A row
    without provenance (a foreign bench) uses its ``degradation_type`` and the ``bench`` preset,
    its metres stated at the reference depth. A degradation whose plugin is not loaded is named
    without ranges.
    """
    if row.is_clean:
        return ""
    steps = [
        (str(d.get("name", "")), str(d.get("preset") or "bench"), _depth(d.get("scene_depth_m")), True)
        for d in row.degradation if d.get("name")
    ]
    if not steps:  # a foreign bench without provenance: its degradation_type, mixtures expanded
        steps = [(c.name, c.preset or "bench", None, False) for c in Chain.parse(row.degradation_type).choices()]
    described = []
    for name, preset, depth, known in steps:
        ranges = _ranges_text(name, preset, depth, known)
        label = name.replace("_", " ")
        described.append(f"{label} (severity given as the rendering parameter ranges: {ranges})" if ranges else label)
    return "The images are degraded by " + " and ".join(described) + ".\n"


def _depth(value: Any) -> float | None:
    """A provenance ``scene_depth_m`` as a positive number of metres, else ``None``."""
    try:
        depth = float(value)
    except (TypeError, ValueError):
        return None
    return depth if math.isfinite(depth) and depth > 0 else None


def conversation(row: BenchRow, variant: str, n_images: int | None = None) -> list[dict[str, Any]]:
    """The first model call of ``variant`` for ``row`` (for ``cot``: stage 1).

    ``n_images`` defaults to the row's image count; ``no_image`` always has none. The question
    text is the row's (option lines included), so the model sees what the bench's TSV holds.
    """
    if variant not in VARIANTS:
        raise ValueError(f"unknown prompt variant {variant!r}; choose one of {', '.join(VARIANTS)}")
    views = len(row.image_paths) if n_images is None else n_images
    if variant == "no_image":
        return chat_messages(row.question, 0)
    if variant == "degradation_info":
        return chat_messages(degradation_info(row) + row.question, views)
    if variant == "cot":
        choices = ", ".join(["clean (no degradation)", *(n.replace("_", " ") for n in known_degradations())])
        return chat_messages(COT_STAGE1_PROMPT.format(choices=choices), views, system=COT_SYSTEM_PROMPT)
    return chat_messages(row.question, views)


def cot_followup(messages: Sequence[Mapping[str, Any]], stage1_answer: str, row: BenchRow) -> list[dict[str, Any]]:
    """Stage 2 of ``cot``: the stage-1 conversation, the model's stage-1 answer, then the
    question with :data:`COT_STAGE2_SUFFIX` (images are not repeated; they are in turn 1)."""
    return [
        *(dict(m) for m in messages),
        {"role": "assistant", "content": [{"type": "text", "text": stage1_answer}]},
        {"role": "user", "content": [{"type": "text", "text": row.question + COT_STAGE2_SUFFIX}]},
    ]


def parse_degradation_guess(text: str, names: Sequence[str] | None = None) -> str | None:
    """The degradation a ``cot`` stage-1 answer names: ``"ori"`` for clean, a plugin name, or
    ``None``. Reads the text after ``Degradation:`` when present, else the whole answer, and
    takes the name or alias (:data:`_ALIASES`) that appears first."""
    names = list(names) if names is not None else known_degradations()
    lowered = text.lower()
    tagged = re.search(r"degradation\s*(?:type)?\s*[:=]\s*(.+)", lowered)
    scope = tagged.group(1) if tagged else lowered
    candidates = {**{n.replace("_", " "): n for n in names}, **{n: n for n in names}, **_ALIASES}
    best: tuple[int, int, str] | None = None
    for word, name in candidates.items():
        match = re.search(rf"(?<![a-z]){re.escape(word)}(?![a-z])", scope)
        if match and (best is None or (match.start(), -len(word)) < best[:2]):
            best = (match.start(), -len(word), name)
    return best[2] if best else None


def prompt_texts() -> dict[str, str]:
    """Every fixed prompt text, recorded in prediction sidecars."""
    return {
        "answer_prompt": ANSWER_PROMPT, "cot_system_prompt": COT_SYSTEM_PROMPT,
        "cot_stage1_prompt": COT_STAGE1_PROMPT, "cot_stage2_suffix": COT_STAGE2_SUFFIX,
    }

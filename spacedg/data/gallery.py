"""A labelled contact sheet of one view: clean, then each degradation at severities 1–5 and ``bench``.

This is the picture a user checks first: does each model look like its name, and does it get
harsher from left to right? Rows are degradations (every registered one, third-party plugins
included, or a chosen subset), columns ``clean | 1 | 2 | 3 | 4 | 5 | bench``. Each thumbnail is
captioned with its preset and the sampled parameter values. All cells come from one
:func:`~spacedg.data.pipeline.degrade_variants` call, so post-render degradations share the
clean render and only raster-stage ones render again.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import cv2
import numpy as np

from spacedg.data.pipeline import (
    DegradedViews,
    PipelineOptions,
    degrade_variants,
    sample_scene_depth,
)
from spacedg.plugins.registry import get_degradation, list_degradations
from spacedg.plugins.specs import SEVERITY_PRESETS
from spacedg.scene.floorplan import contact_sheet

if TYPE_CHECKING:
    from spacedg.scene.model import Scene

__all__ = ["GALLERY_PRESETS", "gallery_sheet"]

#: Column presets after the clean image.
GALLERY_PRESETS: tuple[str, ...] = (*SEVERITY_PRESETS, "bench")
_FONT = cv2.FONT_HERSHEY_SIMPLEX
_CAPTION_LINE = 14  # pixels per caption line
_INK = (20, 20, 20)


def _caption(thumb: np.ndarray, lines: Sequence[str]) -> np.ndarray:
    """``thumb`` with a white strip of text lines below it (each cut to the thumbnail width)."""
    width = thumb.shape[1]
    strip = np.full((_CAPTION_LINE * len(lines) + 4, width, 3), 255, np.uint8)
    for k, text in enumerate(lines):
        while text and cv2.getTextSize(text, _FONT, 0.36, 1)[0][0] > width - 4:  # Hershey fonts are ASCII: '~' marks a cut
            text = text[:-2] + "~" if len(text) > 2 else ""
        cv2.putText(strip, text, (2, _CAPTION_LINE * (k + 1) - 3), _FONT, 0.36, _INK, 1, cv2.LINE_AA)
    return np.concatenate([thumb, strip], axis=0)


def _row_label(name: str, stage: str, height: int, width: int) -> np.ndarray:
    cell = np.full((height, width, 3), 255, np.uint8)
    cv2.putText(cell, name, (4, height // 2 - 4), _FONT, 0.5, _INK, 1, cv2.LINE_AA)
    cv2.putText(cell, f"({stage})", (4, height // 2 + 16), _FONT, 0.4, (90, 90, 90), 1, cv2.LINE_AA)
    return cell


def _params_text(result: DegradedViews) -> str:
    (entry,) = result.degradations
    return " ".join(f"{k}={v:.3g}" for k, v in entry["params"].items())


def _thumbnail(image: np.ndarray, width: int) -> np.ndarray:
    height = max(1, round(image.shape[0] * width / image.shape[1]))
    return cv2.resize(image, (width, height), interpolation=cv2.INTER_AREA)


def gallery_sheet(
    scene: Scene,
    view: str,
    degradations: Sequence[str] | None = None,
    seed: int = 0,
    thumb_width: int = 256,
    options: PipelineOptions | None = None,
    progress: bool = False,
) -> np.ndarray:
    """The labelled contact sheet (uint8 RGB) for ``view`` of ``scene``.

    Args:
        scene: the scene.
        view: the view name.
        degradations: rows, by name (default: every registered degradation, sorted).
        seed: sample seed (parameters and noise drawn from it, as in the pipeline).
        thumb_width: thumbnail width, pixels; images are rendered at the view's own size, so
            pixel-unit parameters (aperture, blur sigma) look as they do in the dataset.
        options: pipeline options (backend, motion quality, image size).
        progress: show a progress bar.
    """
    specs = [get_degradation(n) for n in degradations] if degradations else list_degradations()
    chains = ["clean", *(f"{spec.name}:{preset}" for spec in specs for preset in GALLERY_PRESETS)]
    results = degrade_variants(scene, [view], chains, seed, options, progress=progress)
    depth = sample_scene_depth(scene, [view])
    clean_lines = ["clean" if depth is None else f"clean, scene depth {depth:.2f}", view]
    clean = _caption(_thumbnail(results[0].images[0], thumb_width), clean_lines)
    cells: list[np.ndarray] = []
    for r, spec in enumerate(specs):
        row = results[1 + r * len(GALLERY_PRESETS): 1 + (r + 1) * len(GALLERY_PRESETS)]
        cells.append(_row_label(spec.name, spec.stage.value, clean.shape[0], thumb_width * 2 // 3))
        cells.append(clean)
        for preset, result in zip(GALLERY_PRESETS, row):
            label = "bench" if preset == "bench" else f"severity {preset}"
            cells.append(_caption(_thumbnail(result.images[0], thumb_width), [label, _params_text(result)]))
    return contact_sheet(cells, columns=2 + len(GALLERY_PRESETS), pad=6)

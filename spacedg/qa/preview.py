"""A PNG contact sheet of question records: their clean views, the named objects' boxes, the text.

Each panel shows the record's views side by side (image A, B, … rendered clean at thumbnail
size), the oriented boxes of the objects the question names (``geometry["refs"]``) drawn in
the image where the question says to find them (colour per object: 1 red, 2 blue, 3 green),
and below them the question type, the question, the options with the correct one marked
``*`` and the answer. It is for eyeballing that questions and answers make sense; the answer
itself comes from the record, not from the picture.

Hershey fonts (OpenCV) are ASCII only: ``°``, ``×``, dashes and quotes are transliterated.
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

from spacedg.plugins.qa_record import QARecord
from spacedg.qa.views import render_clean_view
from spacedg.render.camera import Camera
from spacedg.scene.floorplan import contact_sheet
from spacedg.scene.model import Scene

__all__ = ["render_thumbnail", "record_panel", "qa_sheet", "ascii_text"]

_FONT = cv2.FONT_HERSHEY_SIMPLEX
_SCALE = 0.38
_LINE = 14
_INK = (20, 20, 20)
_REF_COLOURS = ((220, 30, 30), (30, 80, 230), (20, 150, 40), (200, 120, 0))
_BOX_EDGES = [(a, b) for a in range(8) for b in range(a + 1, 8) if bin(a ^ b).count("1") == 1]
_ASCII = {"°": " deg", "×": "x", "–": "-", "—": "-", "’": "'", "‘": "'", "“": '"', "”": '"', "≥": ">=", "≤": "<=", "…": "..."}


def ascii_text(text: str) -> str:
    """``text`` with the non-ASCII characters questions use transliterated (others become ``?``)."""
    out = "".join(_ASCII.get(ch, ch) for ch in text)
    return out.encode("ascii", "replace").decode("ascii")


def _wrap(text: str, width: int) -> list[str]:
    lines: list[str] = []
    for paragraph in ascii_text(text).split("\n"):
        line = ""
        for word in paragraph.split(" "):
            trial = f"{line} {word}".strip()
            if line and cv2.getTextSize(trial, _FONT, _SCALE, 1)[0][0] > width - 6:
                lines.append(line)
                line = word
            else:
                line = trial
        lines.append(line)
    return lines


def _text_block(lines: Sequence[str], width: int) -> np.ndarray:
    block = np.full((_LINE * len(lines) + 6, width, 3), 255, np.uint8)
    for k, text in enumerate(lines):
        cv2.putText(block, text, (3, _LINE * (k + 1)), _FONT, _SCALE, _INK, 1, cv2.LINE_AA)
    return block


def render_thumbnail(scene: Scene, view: str, width: int, backend: str = "auto") -> tuple[np.ndarray, Camera]:
    """The clean sRGB view at ``width`` px wide (uint8 H×W×3, the sample pipeline's clean render)
    and the camera it was rendered with."""

    full = scene.camera(view)
    height = max(1, round(full.height * width / full.width))
    return render_clean_view(scene, view, (width, height), backend), full.fitted(width, height)


def _draw_box(image: np.ndarray, cam: Camera, corners: np.ndarray, colour: tuple[int, int, int], tag: str) -> None:
    uv, _, valid = cam.project(corners)
    for a, b in _BOX_EDGES:
        if valid[a] and valid[b]:
            pa = tuple(int(round(v)) for v in uv[a])
            pb = tuple(int(round(v)) for v in uv[b])
            cv2.line(image, pa, pb, colour, 1, cv2.LINE_AA)
    if valid.any():
        top = uv[valid][np.argmin(uv[valid][:, 1])]
        x = int(np.clip(top[0], 2, image.shape[1] - 12))
        y = int(np.clip(top[1] - 3, 10, image.shape[0] - 2))
        cv2.putText(image, tag, (x, y), _FONT, 0.4, colour, 1, cv2.LINE_AA)


def record_panel(
    scene: Scene, record: QARecord, thumbnails: dict[str, tuple[np.ndarray, Camera]], min_width: int = 0,
) -> np.ndarray:
    """One panel: the record's views (from ``thumbnails``: view → (image, camera)) and its text,
    at least ``min_width`` px wide (so one-view panels get as much room for text as two-view ones)."""
    images = {view: thumbnails[view][0].copy() for view in record.views}
    for k, ref in enumerate(record.geometry.get("refs", [])):
        view = str(ref["view"])
        if view in images:
            corners = scene.instance(int(ref["id"])).box.corners()
            _draw_box(images[view], thumbnails[view][1], corners, _REF_COLOURS[k % len(_REF_COLOURS)], str(k + 1))
    letters = "ABCD"
    for k, view in enumerate(record.views):
        cv2.putText(images[view], f"image {letters[k]}", (4, 14), _FONT, 0.45, (255, 255, 255), 2, cv2.LINE_AA)
        cv2.putText(images[view], f"image {letters[k]}", (4, 14), _FONT, 0.45, (0, 0, 0), 1, cv2.LINE_AA)
    height = max(im.shape[0] for im in images.values())
    strip = np.full((height, max(min_width, sum(im.shape[1] for im in images.values()) + 4 * (len(images) - 1)), 3), 255, np.uint8)
    x = 0
    for im in images.values():
        strip[: im.shape[0], x : x + im.shape[1]] = im
        x += im.shape[1] + 4
    width = strip.shape[1]
    lines = [f"{record.question_type} / {record.sub_question_type} ({record.answer_type.value})"]
    lines += _wrap(record.question, width)
    for option in record.options:
        mark = "*" if option.startswith(f"{record.answer}.") else " "
        lines += _wrap(f"{mark} {option}", width)
    if not record.options:
        answer = record.answer
        text = "[" + ", ".join(f"{v:.2f}" for v in answer) + "]" if isinstance(answer, tuple) else str(answer)
        lines.append(f"answer: {text}")
    return np.concatenate([strip, _text_block(lines, width)], axis=0)


def qa_sheet(
    scene: Scene,
    records: Sequence[QARecord],
    *,
    thumb_width: int = 256,
    columns: int = 2,
    backend: str = "auto",
    progress: bool = True,
) -> np.ndarray:
    """A contact sheet (uint8 RGB) of ``records`` of ``scene``, one panel each; every needed view
    is rendered once."""
    from tqdm import tqdm

    if not records:
        raise ValueError("qa_sheet needs at least one record")
    views = sorted({v for r in records for v in r.views})
    thumbnails = {v: render_thumbnail(scene, v, thumb_width, backend) for v in tqdm(views, desc="qa preview", unit="view", disable=not progress)}
    widest = max(sum(thumbnails[v][0].shape[1] + 4 for v in r.views) - 4 for r in records)
    panels = [record_panel(scene, r, thumbnails, min_width=widest) for r in records]
    return contact_sheet(panels, columns=columns)

"""The pictures of docs/degradations-physics.md: the nine degradations on an object in front of
nothing and on a room rendered at two sizes (small PNG contact sheets under docs/images/).

- ``physics_object.png``: one real splat object (``../shared/data/splats/<--object>``, 0.25 m
  across, filmed from 0.5 m at 320×240, nothing behind it; the scene of
  ``benchmarks/answerability.py``): rows = degradations, columns clean | severity 1 | 3 | bench;
- ``physics_room.png``: built-in room 0, one view rendered at 640×480 and at 160×120 (every
  thumbnail shown at the same width): columns clean | severity 1 | bench at each size, so a
  parameter in pixels that does not scale with the image shows as a difference between the two.

Both are saved as 256-colour palette PNGs (a few hundred KB together).

Each cell is captioned ``ok``/``--``: whether the named object (object sheet: the object; room
sheet: the object covering most of the view, room surfaces aside) is discernible in that image
by :mod:`spacedg.data.answerability`.

    PYTHONPATH=$PWD python benchmarks/physics_gallery.py [--out docs/images] [--thumb 120]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

from spacedg.data.answerability import groups_answerability, object_id_maps
from spacedg.data.pipeline import PipelineOptions, degrade_variants
from spacedg.plugins.registry import list_degradations
from spacedg.scene.floorplan import contact_sheet
from spacedg.scene.labelling import STRUCTURAL_LABELS

sys.path.insert(0, str(Path(__file__).resolve().parent))
import answerability as bench  # noqa: E402 - the object scene of the answerability benchmark

_FONT = cv2.FONT_HERSHEY_SIMPLEX


def _cell(image: np.ndarray, width: int, caption: str) -> np.ndarray:
    height = round(image.shape[0] * width / image.shape[1])
    thumb = cv2.resize(image, (width, height), interpolation=cv2.INTER_AREA)
    strip = np.full((14, width, 3), 255, np.uint8)
    cv2.putText(strip, caption, (2, 11), _FONT, 0.33, (20, 20, 20), 1, cv2.LINE_AA)
    return np.concatenate([thumb, strip])


def _label(text: str, like: np.ndarray, width: int = 84) -> np.ndarray:
    cell = np.full((like.shape[0], width, 3), 255, np.uint8)
    cv2.putText(cell, text, (3, like.shape[0] // 2), _FONT, 0.36, (20, 20, 20), 1, cv2.LINE_AA)
    return cell


def _row(scene, view, groups, chains, options, width, seed):
    """Cells of one view under ``chains`` at ``options`` (captions: preset and discernible or not)."""
    results = degrade_variants(scene, [view], chains, seed, options)
    cells = []
    for chain, result in zip(chains, results):
        maps = object_id_maps(scene, [view], result.degradations, options)
        seen = groups_answerability(groups, result.images, maps, [view]).answerable
        name = chain.split(":")[1] if ":" in chain else "clean"
        cells.append(_cell(result.images[0], width, f"{name} {'ok' if seen else '--'}"))
    return cells


def object_sheet(name: str, width: int, seed: int = 3) -> np.ndarray:
    scene, items = bench.object_items(name, 12, (320, 240))
    (view,), groups = items[1]
    options = PipelineOptions(image_size=(320, 240))
    rows = []
    for spec in list_degradations():
        cells = _row(scene, view, groups, ["clean", f"{spec.name}:1", f"{spec.name}:3", f"{spec.name}:bench"], options, width, seed)
        rows += [_label(spec.name, cells[0]), *cells]
    return contact_sheet(rows, columns=5, pad=3)


def _largest_object(scene, view: str, options: PipelineOptions) -> int:
    """The instance covering most of ``view`` that is not a room surface (wall, floor, ceiling, …)."""
    (ids,) = object_id_maps(scene, [view], [], options)
    surfaces = {inst.id for inst in scene.instances if inst.label in STRUCTURAL_LABELS}
    counts = np.bincount(ids[ids >= 0].ravel())
    counts[[i for i in surfaces if i < len(counts)]] = 0
    return int(np.argmax(counts))


def room_sheet(width: int, seed: int = 3) -> np.ndarray:
    from spacedg.scene.synthetic import RoomConfig, generate_room

    scene = generate_room(0, RoomConfig(gaussians=60_000))
    view = list(scene.views)[len(scene.views) // 3]
    groups = [(view, (_largest_object(scene, view, PipelineOptions(image_size=(640, 480))),))]
    rows = []
    for spec in list_degradations():
        chains = ["clean", f"{spec.name}:1", f"{spec.name}:bench"]
        cells = [c for size in ((640, 480), (160, 120)) for c in _row(scene, view, groups, chains, PipelineOptions(image_size=size), width, seed)]
        rows += [_label(spec.name, cells[0]), *cells]
    return contact_sheet(rows, columns=7, pad=3)


def _save_small(sheet: np.ndarray, path: Path) -> None:
    """A 256-colour palette PNG (median cut, no dithering): a third of the RGB PNG's bytes for the docs."""
    from PIL import Image

    Image.fromarray(sheet).quantize(colors=256, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE).save(path, optimize=True)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=Path("docs/images"))
    parser.add_argument("--thumb", type=int, default=120)
    parser.add_argument("--object", default="teapot")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    for name, sheet in (("physics_object.png", object_sheet(args.object, args.thumb)), ("physics_room.png", room_sheet(args.thumb))):
        path = args.out / name
        _save_small(sheet, path)
        print(f"wrote {path} ({sheet.shape[1]}x{sheet.shape[0]}, {path.stat().st_size // 1024} KB)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

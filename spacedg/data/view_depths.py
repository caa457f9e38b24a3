"""Every view's scene depth, measured once per scene and kept with the scene's derived caches.

Depth-relative presets (defocus focus, haze density, motion-blur shake) are resolved at a sample's
scene depth, the median over its views of :func:`~spacedg.data.pipeline.view_depth` (metres). One
view costs a projection of the scene's opaque centres, 3–4 ms on a 150–260k-Gaussian room, and a
process keeps only what it measured itself. At the paper's scale (~400 views a scene and ~1,600
questions, a DataLoader worker of eight meets each view about once an epoch) nearly every sample
paid it.

The table is ``cache/<scene id>.view-depths.npz`` in the scene folder, beside the visibility
caches: every view's depth as :func:`~spacedg.data.pipeline.view_depth` measures it (the same
floats; NaN where a view sees no opaque Gaussian), keyed by the SHA-256 of the scene's
``scene.json`` and this module's method and version, so whether it is current is known without
loading the Gaussians (as for the question index, and with the same caveat: rewriting the splats
in place under the same ``scene.json`` needs the file deleted). :func:`ensure_view_depths`
measures the stale tables of a dataset's scenes before any worker starts, in a separate
interpreter (as the question indexes: the caller starts no numba threads before DataLoader workers
fork); :func:`load_view_depths` reads a table, or measures and writes it where it is missing. A
stale, foreign or unreadable file is measured again and replaced atomically; a folder that cannot
be written keeps the measured values in memory only (the same values; the next process measures
again).
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from spacedg.data.pipeline import DEPTH_GRID, DEPTH_MIN_OPACITY, view_depth
from spacedg.errors import SpaceDGError
from spacedg.qa.index import scene_json_path
from spacedg.scene.derived_cache import read_npz_entry, write_npz_entry
from spacedg.scene.io import load_scene
from spacedg.scene.model import Scene
from spacedg.scene.store import run_isolated

__all__ = ["VIEW_DEPTHS_VERSION", "ensure_view_depths", "load_view_depths", "view_depths_path"]

#: Bumped when :func:`~spacedg.data.pipeline.view_depth` measures differently (older tables are then stale).
VIEW_DEPTHS_VERSION = 1


def view_depths_path(scene_id: str, folder: str | Path) -> Path:
    """``<scene folder>/cache/<scene_id>.view-depths.npz`` (``folder``: the scene folder or its ``scene.json``)."""
    return scene_json_path(folder).parent / "cache" / f"{scene_id}.view-depths.npz"


def _table_key(folder: str | Path) -> str:
    """SHA-256 hex of the scene's ``scene.json`` bytes and the measurement's parameters."""
    digest = hashlib.sha256(scene_json_path(folder).read_bytes())
    params = {"method": "view_depth", "version": VIEW_DEPTHS_VERSION, "grid": list(DEPTH_GRID), "min_opacity": DEPTH_MIN_OPACITY}
    digest.update(json.dumps(params, sort_keys=True).encode())
    return digest.hexdigest()


def _read(scene_id: str, folder: str | Path, names: Sequence[str]) -> np.ndarray | None:
    """The stored depths (float64, in ``names`` order: sorted view names), or ``None`` when the table is
    missing, stale, unreadable or not one value per name."""
    entry = read_npz_entry(view_depths_path(scene_id, folder), _table_key(folder))
    depths = None if entry is None else entry.get("depth")
    if depths is None or depths.shape != (len(names),):
        return None
    return depths


def _measure(scene: Scene, folder: str | Path) -> np.ndarray:
    """Every view's depth (sorted view names; NaN: none), written to the scene folder where it can be."""
    depths = np.array([math.nan if d is None else d for d in (view_depth(scene, scene.camera(n)) for n in sorted(scene.views))], np.float64)
    try:
        write_npz_entry(view_depths_path(scene.id, folder), _table_key(folder), {"depth": depths})
    except OSError:
        pass  # a read-only folder: the values hold for this process (module docstring)
    return depths


def load_view_depths(scene: Scene, folder: str | Path) -> dict[str, float | None]:
    """``{view name: its scene depth in metres, or None where the view sees no opaque Gaussian}`` for every
    view of ``scene`` (loaded from ``folder``): read from the table, or measured and written there."""
    names = sorted(scene.views)
    depths = _read(scene.id, folder, names)
    if depths is None:
        depths = _measure(scene, folder)
    return {name: None if math.isnan(d) else float(d) for name, d in zip(names, depths.tolist())}


def ensure_view_depths(dirs: Sequence[Path]) -> dict[str, str]:
    """Measure the view-depth table of each scene folder in ``dirs`` whose table is missing or stale, in a
    separate interpreter (module docstring); returns ``folder → error`` for those that failed (their
    samples then measure their views themselves)."""
    stale = []
    failed: dict[str, str] = {}
    for folder in dirs:
        try:
            scene = load_scene(folder)  # the cameras; the Gaussians are read only where the table is measured
            if _read(scene.id, folder, sorted(scene.views)) is None:
                stale.append(str(folder))
        except (SpaceDGError, OSError, ValueError) as err:
            failed[str(folder)] = str(err)
    if stale:
        failed.update(run_isolated("spacedg.data.view_depths:_measure_folders", {"dirs": stale}))
    return failed


def _measure_folders(payload: dict[str, Any]) -> dict[str, str]:
    """Child side of :func:`ensure_view_depths`: measure and write the tables of ``payload["dirs"]``."""
    from tqdm import tqdm

    failed: dict[str, str] = {}
    for folder in tqdm(payload["dirs"], desc="view depths (first use)", unit="scene"):
        try:
            _measure(load_scene(folder), folder)
        except (SpaceDGError, OSError, ValueError) as err:
            failed[folder] = str(err)
    return failed

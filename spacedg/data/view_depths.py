"""Every view's scene depth, measured once per scene and kept with the scene's derived caches.

Depth-relative presets (defocus focus, haze density, motion-blur shake) are resolved at a sample's
scene depth, the median over its views of :func:`~spacedg.data.pipeline.view_depth` (metres). One
view costs a projection of the scene's opaque centres, 3–4 ms on a 150–260k-Gaussian room, and a
process keeps only what it measured itself. At the paper's scale (~400 views a scene and ~1,600
questions, a DataLoader worker of eight meets each view about once an epoch) nearly every sample
paid it.

The table is ``cache/<scene id>.view-depths.npz`` in the scene folder, beside the visibility
caches: every view's depth as :func:`~spacedg.data.pipeline.view_depth` measures it (the same
floats; NaN where a view sees no opaque Gaussian). It is keyed by the SHA-256 of the scene's
``scene.json`` (which records the Gaussians' file and its SHA-256), the grid, the opacity floor and
the source of the code that measures, so a changed scene or a changed measurement makes it stale,
and whether it is current is known without loading the Gaussians. :func:`ensure_view_depths`
measures the stale tables of a dataset's scenes before any worker starts, in a separate
interpreter (as the question indexes: the caller starts no numba threads before DataLoader workers
fork); :func:`read_view_depths` reads one and never measures: a scene without a current table
(a folder that cannot be written, a failed measurement) measures each view a sample needs, as
before, and the values are the same either way.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.util
import inspect
import json
import math
import os
import warnings
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from spacedg.data import pipeline
from spacedg.errors import InvalidDataError
from spacedg.qa.index import scene_json_path
from spacedg.scene.derived_cache import read_npz_entry, write_npz_entry
from spacedg.scene.io import load_scene
from spacedg.scene.model import Scene
from spacedg.scene.store import each_folder, run_isolated, stale_folders

__all__ = ["ensure_view_depths", "read_view_depths", "view_depths_path"]


def view_depths_path(scene_id: str, folder: str | Path) -> Path:
    """``<scene folder>/cache/<scene_id>.view-depths.npz`` (``folder``: the scene folder or its ``scene.json``)."""
    return scene_json_path(folder).parent / "cache" / f"{scene_id}.view-depths.npz"


@functools.cache
def _method_digest() -> str:
    """SHA-256 of what a view's depth depends on besides the scene: the grid, the opacity floor, and the
    source of :func:`~spacedg.data.pipeline.view_depth`, its opaque-centre helpers and its compiled step
    (read from its file: the check imports no numba)."""
    digest = hashlib.sha256(json.dumps({"grid": list(pipeline.DEPTH_GRID), "min_opacity": pipeline.DEPTH_MIN_OPACITY}).encode())
    for function in (pipeline.view_depth, pipeline._opaque_means, pipeline._opaque_centres):
        digest.update(inspect.getsource(function).encode())
    spec = importlib.util.find_spec("spacedg.data.view_depth_cpu")
    if spec is not None and spec.origin is not None:
        digest.update(Path(spec.origin).read_bytes())
    return digest.hexdigest()


def _table_key(folder: str | Path) -> str:
    """The table's key: SHA-256 of the scene's ``scene.json`` bytes and :func:`_method_digest`."""
    digest = hashlib.sha256(scene_json_path(folder).read_bytes())
    digest.update(_method_digest().encode())
    return digest.hexdigest()


def _stored(scene_id: str, folder: str | Path) -> np.ndarray | None:
    """The current table's depths (float64, one per view in sorted name order), or ``None``."""
    entry = read_npz_entry(view_depths_path(scene_id, folder), _table_key(folder))
    return None if entry is None else entry.get("depth")


def read_view_depths(scene: Scene, folder: str | Path) -> dict[str, float | None] | None:
    """``{view name: its scene depth in metres, or None where the view sees no opaque Gaussian}`` for every
    view of ``scene`` (loaded from ``folder``) from its current table; ``None`` without one (nothing is measured)."""
    names = sorted(scene.views)
    depths = _stored(scene.id, folder)
    if depths is None or depths.shape != (len(names),):
        return None
    return {name: None if math.isnan(d) else float(d) for name, d in zip(names, depths.tolist())}


def ensure_view_depths(folders: Mapping[str, Path]) -> None:
    """Measure and write the table of each scene (``scene id → folder``) whose table is missing or stale, in a
    separate interpreter (module docstring). A folder whose ``cache`` cannot be written is left alone; a
    scene that fails is named in a warning (its samples measure their views, as before)."""
    ids = {str(folder): scene_id for scene_id, folder in folders.items()}
    stale, failed = stale_folders(list(ids), lambda folder: _stored(ids[str(folder)], folder) is not None)
    stale = [folder for folder in stale if _writable(view_depths_path(ids[folder], folder).parent)]
    if stale:
        try:
            failed.update(run_isolated("spacedg.data.view_depths:_measure_folders", {"dirs": stale}))
        except InvalidDataError as err:
            failed.update(dict.fromkeys(stale, str(err)))
    if failed:
        listing = "; ".join(f"{folder}: {error}" for folder, error in failed.items())
        warnings.warn(f"view depths not stored for {len(failed)} scene(s) (their samples measure them): {listing}", stacklevel=3)


def _writable(cache: Path) -> bool:
    """Whether ``cache`` (a scene's cache folder, perhaps not made yet) can take a file."""
    existing = cache if cache.exists() else cache.parent
    return os.access(existing, os.W_OK | os.X_OK)


def _measure(folder: str) -> None:
    """Measure every view of the scene in ``folder`` and write its table."""
    scene = load_scene(folder)
    depths = [pipeline.view_depth(scene, scene.camera(name)) for name in sorted(scene.views)]
    values = np.array([math.nan if d is None else d for d in depths], np.float64)
    write_npz_entry(view_depths_path(scene.id, folder), _table_key(folder), {"depth": values})


def _measure_folders(payload: dict[str, Any]) -> dict[str, str]:
    """Child side of :func:`ensure_view_depths`: ``folder → error`` for the scenes that failed."""
    return each_folder(payload["dirs"], "view depths (first use)", _measure)

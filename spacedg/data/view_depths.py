"""Every view's scene depth, measured once per scene and kept with the scene's derived caches.

Depth-relative presets (defocus focus, haze density, motion-blur shake) are resolved at a sample's
scene depth, the median over its views of :func:`~spacedg.data.pipeline.view_depth` (metres). One
view costs a projection of the scene's opaque centres: 3–4 ms on a 150–260k-Gaussian room, about
50 ms at 2 M Gaussians. A process kept only what it measured itself, and at the paper's scale
(~400 views a scene and ~1,600 questions, a DataLoader worker of eight meets each view about once
an epoch) nearly every sample paid it.

The table is ``cache/<scene id>.view-depths.npz`` in the scene folder, beside the visibility
caches: every view's depth as :func:`~spacedg.data.pipeline.view_depth` measures it (the same
floats; NaN where a view sees no opaque Gaussian). It is keyed by the SHA-256 of the scene's
``scene.json`` (which records the Gaussians' file and its SHA-256), the grid, the opacity floor and
the files of the code that measures, so a changed scene or a changed measurement makes it stale.
:func:`ensure_view_depths` reads it, or measures every view and writes it: the first process that
needs a scene's depths pays for the whole scene once (about what a worker paid over an epoch view
by view), and every later one reads it. A stale, foreign or unreadable file is measured again and
replaced atomically (two processes measuring at once write the same values); a folder that cannot
be written keeps the measured values in the process only.
"""

from __future__ import annotations

import functools
import hashlib
import json
import math
from pathlib import Path

import numpy as np

from spacedg.data import pipeline
from spacedg.qa.index import module_files_digest, scene_json_path
from spacedg.scene.derived_cache import read_npz_entry, write_npz_entry
from spacedg.scene.model import Scene

__all__ = ["ensure_view_depths", "view_depths_path"]


def view_depths_path(scene_id: str, folder: str | Path) -> Path:
    """``<scene folder>/cache/<scene_id>.view-depths.npz`` (``folder``: the scene folder or its ``scene.json``)."""
    return scene_json_path(folder).parent / "cache" / f"{scene_id}.view-depths.npz"


def _table_key(folder: str | Path) -> str:
    """The table's key: SHA-256 of the scene's ``scene.json`` bytes, the grid, the opacity floor and the files
    of the code that measures (:func:`~spacedg.data.pipeline.view_depth` and its compiled step)."""
    digest = hashlib.sha256(scene_json_path(folder).read_bytes())
    digest.update(json.dumps({"grid": list(pipeline.DEPTH_GRID), "min_opacity": pipeline.DEPTH_MIN_OPACITY}).encode())
    digest.update(_code_digest().encode())
    return digest.hexdigest()


@functools.cache
def _code_digest() -> str:
    """The measuring code's files (:func:`~spacedg.data.pipeline.view_depth` and its compiled step), hashed
    once per process: the code this process runs."""
    return str(module_files_digest(["spacedg.data.pipeline", "spacedg.data.view_depth_cpu"]))


def ensure_view_depths(scene: Scene, folder: str | Path) -> None:
    """Make this process hold the depth of every view of ``scene`` (loaded from ``folder``): nothing when it
    does, else from its table, else measured and written (module docstring)."""
    if pipeline.view_depths_known(scene):
        return
    names = sorted(scene.views)
    path, key = view_depths_path(scene.id, folder), _table_key(folder)
    entry = read_npz_entry(path, key)
    depths = None if entry is None else entry.get("depth")
    if depths is not None and depths.shape == (len(names),):
        pipeline.remember_view_depths(scene, {name: None if math.isnan(d) else float(d) for name, d in zip(names, depths.tolist())})
        return
    measured = [pipeline.view_depth(scene, scene.camera(name)) for name in names]
    try:
        write_npz_entry(path, key, {"depth": np.array([math.nan if d is None else d for d in measured], np.float64)})
    except OSError:
        pass  # a folder that cannot be written: the values hold for this process (module docstring)

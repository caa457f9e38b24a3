"""Scenes for a dataset: where they come from, which split they belong to, and a byte-bounded cache.

- :func:`builtin_scene_dirs`: the procedural rooms, generated once into a cache folder
  (``$SPACEDG_HOME/rooms-v2``, default ``~/.cache/spacedg/rooms-v2``; :data:`BUILTIN_ROOMS_FOLDER`)
  with a progress bar.
- :func:`assign_splits`: scenes → ``train`` / ``val`` / ``bench``, disjoint, deterministic.
- :func:`run_isolated`: run a function in a fresh Python interpreter (the built-in rooms here;
  question indexes in :func:`spacedg.qa.build.ensure_indexes`), so the calling process never
  starts numba or CUDA threads before a DataLoader forks its workers.
- :class:`ByteLRU`: a least-recently-used cache bounded by a byte budget (Gaussians, clean renders).
"""

from __future__ import annotations

import hashlib
import os
from collections import OrderedDict
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from spacedg._checks import check_fractions, check_int, short_repr
from spacedg.errors import InvalidDataError, ParameterError
from spacedg.scene.io import save_scene
from spacedg.scene.synthetic import generate_room

__all__ = ["BUILTIN_ROOMS_FOLDER", "SPLITS", "spacedg_home", "builtin_scene_dirs", "assign_splits", "run_isolated", "ByteLRU", "scene_dirs_of"]

#: The built-in rooms' cache folder under :func:`spacedg_home`, named by the generator's version: rooms
#: generated before wall rows (``rooms``, v1) differ from today's for the same seed, so a cache of
#: them is never silently reused (it stays on disk; delete it by hand).
BUILTIN_ROOMS_FOLDER = "rooms-v2"

#: The dataset splits, disjoint by scene.
SPLITS: tuple[str, ...] = ("train", "val", "bench")


def spacedg_home() -> Path:
    """``$SPACEDG_HOME`` or ``~/.cache/spacedg``: where built-in rooms and their indexes are cached."""
    return Path(os.environ.get("SPACEDG_HOME", Path.home() / ".cache" / "spacedg"))


def _generate_rooms(payload: dict[str, Any]) -> dict[str, str]:
    """Child side of :func:`builtin_scene_dirs`: generate the rooms ``payload["seeds"]`` into ``payload["root"]``."""
    from tqdm import tqdm


    root, seeds = payload["root"], payload["seeds"]
    for seed in tqdm(seeds, desc="built-in rooms (first use)", unit="room"):
        folder = Path(root) / f"room-{seed:06d}"
        if not (folder / "scene.json").is_file():
            save_scene(generate_room(seed, scene_id=folder.name), folder)
    return {}


def builtin_scene_dirs(n: int = 16, root: str | os.PathLike[str] | None = None) -> list[Path]:
    """Folders of the built-in rooms ``room-000000`` … (seeds ``0 … n-1``), generated when missing."""
    if isinstance(n, bool) or not isinstance(n, int) or n < 3:
        raise ParameterError(f"builtin_scene_dirs: n must be an integer >= 3 (one scene per split at least), got {n!r}")
    folder = Path(root) if root is not None else spacedg_home() / BUILTIN_ROOMS_FOLDER
    folder.mkdir(parents=True, exist_ok=True)
    missing = [s for s in range(n) if not (folder / f"room-{s:06d}" / "scene.json").is_file()]
    if missing:
        run_isolated("spacedg.scene.store:_generate_rooms", {"root": str(folder), "seeds": missing})
    return [folder / f"room-{s:06d}" for s in range(n)]


def scene_dirs_of(paths: Sequence[str | os.PathLike[str]]) -> list[Path]:
    """Scene folders from folders, folders of folders, or ``scene.json`` paths (sorted, deduplicated)."""
    if isinstance(paths, (str, bytes, os.PathLike)) or not all(isinstance(p, (str, os.PathLike)) for p in paths):
        raise ParameterError(f"scene_dirs_of: paths must be a list of folder paths, got {short_repr(paths)}")
    found: list[Path] = []
    for raw in paths:
        path = Path(raw)
        if (path / "scene.json").is_file():
            found.append(path)
        elif path.is_file() and path.name == "scene.json":
            found.append(path.parent)
        elif path.is_dir() and any(path.glob("*/scene.json")):
            found.extend(sorted(p.parent for p in path.glob("*/scene.json")))
        elif path.is_dir():
            raise InvalidDataError(f"{path}: no scene.json in it or in its sub-folders; import a capture with `spacedg scenes import SRC --out DIR` (INRIA, COLMAP, nerfstudio, ScanNet++) or build rooms with `spacedg scenes synth`")
        else:
            raise InvalidDataError(f"{path}: no such scene folder")
    return sorted(set(found), key=lambda p: (p.name, str(p)))


def assign_splits(scene_ids: Sequence[str], fractions: tuple[float, float] = (0.1, 0.1), seed: int = 0) -> dict[str, str]:
    """``scene id → split``. ``fractions = (val, bench)``: scenes are ordered by ``sha256(seed:id)``;
    the first ``ceil(bench·n)`` go to ``bench``, the next ``ceil(val·n)`` to ``val``, the rest to
    ``train``. A fraction of 0 leaves its split empty; ``(0, 1)`` puts every scene in ``bench``
    (``spacedg export --all-bench``), which works from one scene. Otherwise every split with a
    positive fraction (and ``train``, unless the fractions sum to 1) gets at least one scene, so
    that needs as many scenes as non-empty splits. Adding a scene moves few others."""
    import math

    if isinstance(scene_ids, (str, bytes)) or not all(isinstance(s, str) for s in scene_ids):
        raise ParameterError(f"assign_splits: scene_ids must be a list of scene id strings, got {short_repr(scene_ids)}")
    check_int(seed, "assign_splits: seed")
    ids = sorted(set(scene_ids))
    val_f, bench_f = check_fractions(fractions, "assign_splits: fractions")
    wanted = (bench_f > 0) + (val_f > 0) + (val_f + bench_f < 1.0 - 1e-9)
    if len(ids) < max(1, wanted):
        raise InvalidDataError(
            f"need at least {max(1, wanted)} scenes to make the {wanted} disjoint split(s) of fractions (val {val_f:g}, bench {bench_f:g}), "
            f"got {len(ids)}: {ids}. To put every scene in the bench pass --all-bench (split_fractions=(0, 1))"
        )
    order = sorted(ids, key=lambda s: hashlib.sha256(f"{seed}:{s}".encode()).hexdigest())
    n_bench = max(1, math.ceil(bench_f * len(ids))) if bench_f > 0 else 0
    n_val = max(1, math.ceil(val_f * len(ids))) if val_f > 0 else 0
    if val_f + bench_f >= 1.0 - 1e-9:
        n_val = len(ids) - n_bench if val_f > 0 else 0
        n_bench = len(ids) - n_val
    elif n_bench + n_val >= len(ids):  # keep one scene for train
        n_val = max(0, len(ids) - 1 - n_bench)
    out = {}
    for k, scene_id in enumerate(order):
        out[scene_id] = "bench" if k < n_bench else "val" if k < n_bench + n_val else "train"
    return out


def run_isolated(target: str, payload: dict[str, Any]) -> dict[str, str]:
    """Run ``target`` (``"package.module:function"``, called with ``payload``) in a fresh interpreter.

    The function takes the JSON-serialisable ``payload`` and returns a ``str → str`` mapping
    (e.g. folder → error message), which comes back as this call's result.

    A separate interpreter, not ``multiprocessing`` spawn: spawn re-imports the caller's main
    script, which breaks scripts without an ``if __name__ == "__main__"`` guard. The child's
    progress bars go to this process's stderr; it answers with a JSON object on stdout.
    """
    import json
    import subprocess
    import sys

    proc = subprocess.run(
        [sys.executable, "-c", "from spacedg.scene.store import _main; _main()", target],
        input=json.dumps(payload), stdout=subprocess.PIPE, stderr=None, text=True, check=False,
    )
    if proc.returncode != 0:
        raise InvalidDataError(f"spacedg {target} failed in its worker process (exit code {proc.returncode}); see the error printed above")
    return dict(json.loads(proc.stdout.strip().splitlines()[-1] if proc.stdout.strip() else "{}"))


class ByteLRU:
    """A least-recently-used mapping bounded by total ``size_of(value)`` bytes.

    An item larger than the budget is returned to the caller but not kept.
    """

    def __init__(self, max_bytes: int, size_of: Callable[[Any], int]) -> None:
        check_int(max_bytes, "ByteLRU: max_bytes", minimum=0)
        if not callable(size_of):
            raise ParameterError(f"ByteLRU: size_of must be a function value → bytes, got {short_repr(size_of)}")
        self.max_bytes = int(max_bytes)
        self.size_of = size_of
        self._items: OrderedDict[Any, tuple[Any, int]] = OrderedDict()
        self.bytes = 0
        self.hits = 0
        self.misses = 0

    def get(self, key: Any, make: Callable[[], Any]) -> Any:
        if key in self._items:
            self._items.move_to_end(key)
            self.hits += 1
            return self._items[key][0]
        self.misses += 1
        value = make()
        size = int(self.size_of(value))
        if size <= self.max_bytes:
            self._items[key] = (value, size)
            self.bytes += size
            while self.bytes > self.max_bytes:
                _, (_, old) = self._items.popitem(last=False)
                self.bytes -= old
        return value

    def __len__(self) -> int:
        return len(self._items)


def _main() -> None:
    """``python -c "…_main()" module:function`` with a JSON payload on stdin (see :func:`run_isolated`)."""
    import importlib
    import json
    import sys

    module_name, _, function = sys.argv[-1].partition(":")
    payload = json.loads(sys.stdin.read())
    result = getattr(importlib.import_module(module_name), function)(payload)
    print(json.dumps(result))

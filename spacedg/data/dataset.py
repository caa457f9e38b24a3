"""``SpaceDGDataset``: degraded multi-view question samples rendered online, for PyTorch.

A map-style :class:`torch.utils.data.Dataset`. Its length and every item are a pure function of
the arguments (the seed, the scenes and their question indexes), whatever process or worker
renders them.

- **Scenes**: native scene folders (``scenes=[...]``), or by default the built-in procedural
  rooms (:func:`~spacedg.scene.store.builtin_scene_dirs`, generated on first use). Each
  scene goes to one split (:func:`~spacedg.scene.store.assign_splits`), so ``train``,
  ``val`` and ``bench`` never share a scene.
- **Questions**: each scene's question index (:mod:`spacedg.data.qa_index`), built on first use
  in a *spawned* process; optionally restricted to ``question_types``.
- **Degradations**:
  - ``train`` / ``val``: one item per question. The item is clean with probability
    ``clean_prob``, otherwise one chain drawn uniformly from ``degradations``. Names without a
    preset take ``severity``, which is ``"bench"`` (the paper's table), ``"1"``–``"5"``, or
    ``"random"`` (a seeded severity per item); mixtures keep their own recipe.
    :meth:`set_epoch` redraws the choices per epoch (shared memory, so persistent workers see it).
  - ``bench``: every question under clean and under each chain of ``degradations`` (default:
    the paper's nine at ``bench``), i.e. ``questions × 10`` items.
  - ``degradations`` also accepts ``"all"`` (every registered degradation, third-party
    included), mixture recipes (``"night_capture"``), presets (``"haze:3"``) and chains
    (``"haze+low_res"``).
- **Item**: a dict with ``images`` (uint8 tensor ``V×3×H×W``, RGB), ``question``, ``options``,
  ``answer``, ``question_type``, ``sub_question_type``, ``task_group``, ``answer_type``,
  ``degradation`` (provenance list), ``degradation_type`` (``"ori"`` for clean, else the chain's
  name), ``scene_id``, ``views``, ``record_id``, ``index``.
- **Workers**: the dataset object holds only paths and small records, so it pickles cheaply.
  Scenes load lazily inside each worker into a byte-bounded LRU cache. Construction never
  renders (indexes are built in a separate Python process), so no numba or CUDA state exists
  before a DataLoader forks. Rendering in the main process first (``dataset[0]`` before the
  DataLoader) is fine too: a worker forked after numba's OpenMP threads started runs
  spacedg's kernels serially (:mod:`spacedg.render.threads`) and gives the same bytes.
  :attr:`SpaceDGDataset.workers` is a worker count chosen from the machine
  (:mod:`spacedg.data.workers`: ``min(8, cores // 2)``), for
  ``DataLoader(dataset, num_workers=dataset.workers)``; each worker renders with
  :attr:`SpaceDGDataset.render_threads` numba threads (``cores // (workers + 1)``).
- **GPU** (``device="cuda"``): renders (``backend="auto"`` → gsplat's CUDA compositor when it
  loads) and degrades on the GPU in the process that owns it. DataLoader workers must not touch
  CUDA (a forked child cannot, and one CUDA context per worker wastes memory), so ``__getitem__``
  in a worker refuses with the fix: either ``num_workers=0``, or ``defer_render=True`` — workers
  then return items without ``images`` (planning, question text, provenance) and the main process
  renders each batch with :meth:`render_batch` (``collate_fn=list`` keeps the items as dicts).
- **Bench split**: ``severity`` does not apply (the protocol is the ``bench`` preset); use
  ``degradations=["haze:3", ...]`` for other levels. With several workers, batch sizes that
  are multiples of ``len(chains) + 1`` keep a question's variants in one worker, where they
  share the clean render.

:func:`spacedg.data.chat.chat_collate` turns a batch into chat messages for a transformers processor.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch.utils.data import Dataset

from spacedg.data.chain import BENCH_DEGRADATIONS, SEVERITIES, Chain
from spacedg.data.pipeline import (
    PipelineOptions,
    degrade,
    frames_nbytes,
    sample_scene_depth,
)
from spacedg.data.qa_index import QABuildConfig, ensure_indexes, index_paths, read_index
from spacedg.data.workers import loader_plan
from spacedg.errors import InvalidDataError, ParameterError
from spacedg.plugins.qa_record import QARecord
from spacedg.plugins.registry import get_question_family, list_degradations
from spacedg.scene.io import load_scene
from spacedg.scene.store import (
    SPLITS,
    ByteLRU,
    assign_splits,
    builtin_scene_dirs,
    scene_dirs_of,
)
from spacedg.seeding import derive_seed

__all__ = ["SpaceDGDataset"]

_SEVERITIES = (*SEVERITIES, "random")


class SpaceDGDataset(Dataset):
    """Online degraded SpaceDG samples (see the module docstring).

    Args:
        split: ``"train"``, ``"val"`` or ``"bench"``.
        degradations: chains (names, ``name:preset``, mixtures, ``a+b``), or ``"all"``; ``None``
            means the nine paper degradations for ``bench`` and clean only for ``train``/``val``.
        scenes: scene folders (or folders of them); default: the built-in rooms.
        question_types: keep only these families (default: all).
        severity: preset for chains named without one: ``"bench"``, ``"1"``–``"5"`` or ``"random"``.
        clean_prob: probability of a clean item in ``train``/``val`` (ignored by ``bench``).
        image_size: ``(width, height)`` to render at, or ``None`` for the views' own size.
        seed: seed of the degradation choices and their noise (not of the splits or questions).
        cache: byte budget of each worker's LRU cache of scenes (their Gaussians) and clean
            renders (shared by every chain without a raster step), default 2 GiB.
        qa_config: how the question indexes are built (default: ``QABuildConfig()``, seed 0:
            each scene's full index ``<scene id>.qa.jsonl``, shared by every dataset over the
            same folders; a config naming ``families`` reads that selection's own index file,
            :func:`~spacedg.data.qa_index.index_paths`).
        split_fractions: ``(val, bench)`` share of scenes; ``(0, 1)`` puts every scene (even one) in
            ``bench`` (see :func:`~spacedg.scene.store.assign_splits`).
        split_seed: seed of the scene → split assignment (kept apart from ``seed`` so that
            changing the augmentation seed never moves a scene between splits).
        on_bad_scene: ``"raise"`` (default) or ``"skip"`` a scene that cannot be read or indexed
            (skipped scenes are named in a warning and in :attr:`skipped`).
        backend: renderer backend (``"auto"``, ``"cpu"``, ``"torch"``, ``"gsplat"``).
        device: torch device; a non-CPU device renders and degrades there, in the main process only
            (module docstring).
        defer_render: items come without ``images``, ``degradation`` and ``stats``; :meth:`render_batch` renders
            them, in the process that owns the GPU.
        builtin_rooms: how many built-in rooms when ``scenes`` is not given.
        max_questions: keep at most this many questions, spread over question types
            round-robin in a seeded order (a small bench or a quick run); ``None`` keeps all.
        workers: DataLoader workers to use with this dataset (:attr:`workers`, for
            ``DataLoader(dataset, num_workers=dataset.workers)``); ``None``: chosen from the
            machine by :func:`~spacedg.data.workers.loader_plan` (``min(8, cores // 2)``).
        render_threads: numba threads each DataLoader worker renders with (set in the worker
            on its first item); ``None``: ``cores // (workers + 1)`` for the DataLoader's
            actual worker count. The main process (``workers = 0``) keeps numba's default.
    """

    def __init__(
        self,
        split: str = "train",
        degradations: Any = None,
        *,
        scenes: Sequence[str | os.PathLike[str]] | None = None,
        question_types: Sequence[str] | None = None,
        severity: str = "bench",
        clean_prob: float = 0.1,
        image_size: tuple[int, int] | None = None,
        seed: int = 0,
        cache: int = 2 << 30,
        qa_config: QABuildConfig | None = None,
        split_fractions: tuple[float, float] = (0.1, 0.1),
        split_seed: int = 0,
        on_bad_scene: str = "raise",
        backend: str = "auto",
        device: str | None = None,
        builtin_rooms: int = 16,
        max_questions: int | None = None,
        defer_render: bool = False,
        workers: int | None = None,
        render_threads: int | None = None,
    ) -> None:
        if split not in SPLITS:
            raise ParameterError(f"SpaceDGDataset: split must be one of {list(SPLITS)}, got {split!r}")
        if severity not in _SEVERITIES:
            raise ParameterError(f"SpaceDGDataset: severity must be one of {list(_SEVERITIES)}, got {severity!r}")
        if isinstance(clean_prob, bool) or not isinstance(clean_prob, (int, float)) or not 0.0 <= float(clean_prob) <= 1.0:
            raise ParameterError(f"SpaceDGDataset: clean_prob must be in [0, 1], got {clean_prob!r}")
        if on_bad_scene not in ("raise", "skip"):
            raise ParameterError(f"SpaceDGDataset: on_bad_scene must be 'raise' or 'skip', got {on_bad_scene!r}")
        self.split, self.severity, self.clean_prob, self.seed = split, severity, float(clean_prob), int(seed)
        plan = loader_plan(workers=workers, render_threads=render_threads)
        #: DataLoader workers suggested for this dataset and numba threads per worker (see spacedg.data.workers).
        self.workers, self.render_threads = plan.workers, plan.render_threads
        self._threads_given = render_threads is not None
        self._threads_set = False
        self.options = PipelineOptions(image_size=tuple(image_size) if image_size else None, backend=backend, device=device)
        self.defer_render = bool(defer_render)
        self._on_device = device is not None and str(device) != "cpu" and not str(device).startswith("cpu:")
        self.chains = self._chains(degradations)
        self.qa_config = qa_config or QABuildConfig()
        dirs = scene_dirs_of(scenes) if scenes is not None else builtin_scene_dirs(builtin_rooms)
        self.skipped: dict[str, str] = {}
        failed = ensure_indexes(dirs, self.qa_config)
        if failed:
            listing = "; ".join(f"{d}: {e}" for d, e in failed.items())
            if on_bad_scene == "raise":
                raise InvalidDataError(f"{len(failed)} scene(s) cannot be used: {listing}. Fix or remove them, or pass on_bad_scene='skip'")
            warnings.warn(f"SpaceDGDataset: skipping {len(failed)} scene(s): {listing}", stacklevel=2)
            self.skipped = dict(failed)
        all_dirs = list(dirs)
        dirs = [d for d in dirs if str(d) not in failed]
        records_by_dir = {d: self._records(d) for d in dirs}
        ids = {d: recs[0].scene_id if recs else d.name for d, recs in records_by_dir.items()}
        # skipped scenes keep their place in the assignment, so skipping never moves another scene
        every_id = [ids.get(d, d.name) for d in all_dirs]
        splits = assign_splits(every_id, split_fractions, seed=int(split_seed))
        self.scene_splits: dict[str, str] = dict(splits)  # every scene id → its split (what went where)
        self.scene_dirs: dict[str, Path] = {ids[d]: d for d in dirs if splits[ids[d]] == split}
        wanted = self._question_types(question_types)
        self.records: list[QARecord] = [
            r for d in dirs if splits[ids[d]] == split for r in records_by_dir[d] if wanted is None or r.question_type in wanted
        ]
        if max_questions is not None:
            self.records = _spread_subset(self.records, int(max_questions), derive_seed(int(split_seed), "subset", split))
        # shared memory: set_epoch() in the main process reaches persistent DataLoader workers
        self._epoch = torch.zeros((), dtype=torch.int64).share_memory_()
        self._cache_bytes = int(cache)
        self._scenes: ByteLRU | None = None  # created lazily in each worker

    # ------------------------------------------------------------ construction
    def _chains(self, degradations: Any) -> list[str]:
        """Canonical chain texts; unknown names, presets and repeats fail here, with suggestions."""
        if degradations is None:
            items: list[Any] = list(BENCH_DEGRADATIONS) if self.split == "bench" else []
        elif isinstance(degradations, str) and degradations == "all":
            items = [spec.name for spec in list_degradations()]
        elif isinstance(degradations, (str, Chain)):
            items = [degradations]
        else:
            items = list(degradations)
        random_levels = self.severity == "random" and self.split != "bench"
        chains = []
        for item in items:
            chain = Chain.parse(item)
            if self.severity != "random":
                chain = chain.with_severity(self.severity)
            chain.check(SEVERITIES[1:] if random_levels else (None,))
            chains.append(chain.text)
        if len(set(chains)) != len(chains):
            raise ParameterError(f"SpaceDGDataset: degradations repeat a chain: {chains}")
        return chains

    def _records(self, folder: Path) -> list[QARecord]:
        jsonl, _ = index_paths(load_scene(folder).id, folder, self.qa_config.families)
        return read_index(jsonl)

    @staticmethod
    def _question_types(question_types: Sequence[str] | None) -> set[str] | None:
        if question_types is None:
            return None
        return {get_question_family(name).name for name in question_types}  # unknown names fail with suggestions

    # ------------------------------------------------------------ indexing
    def __len__(self) -> int:
        return len(self.records) * (len(self.chains) + 1 if self.split == "bench" else 1)

    @property
    def epoch(self) -> int:
        return int(self._epoch)

    def set_epoch(self, epoch: int) -> None:
        """Redraw the train/val degradation choices for ``epoch`` (like ``DistributedSampler.set_epoch``);
        the value lives in shared memory, so persistent DataLoader workers see it too."""
        self._epoch.fill_(int(epoch))

    def plan(self, index: int) -> tuple[QARecord, str | None, str]:
        """``(record, chain or None for clean, degradation_type)`` of item ``index`` (no rendering)."""
        if not 0 <= index < len(self):
            raise IndexError(f"SpaceDGDataset index {index} out of range [0, {len(self)})")
        if self.split == "bench":
            record = self.records[index // (len(self.chains) + 1)]
            k = index % (len(self.chains) + 1)
            chain = None if k == 0 else self.chains[k - 1]
        else:
            record = self.records[index]
            rng = np.random.default_rng(derive_seed(self.seed, "choice", self.epoch, record.id))
            chain = None if (not self.chains or rng.random() < self.clean_prob) else self.chains[int(rng.integers(len(self.chains)))]
            if chain is not None and self.severity == "random":
                chain = Chain.parse(chain).with_severity(str(int(rng.integers(1, 6)))).text
        return record, chain, Chain.parse(chain).name

    def _sample_seed(self, record: QARecord, name: str) -> int:
        return derive_seed(self.seed, "sample", record.id, name, self.epoch if self.split != "bench" else 0)

    def provenance(self, index: int) -> list[dict[str, Any]]:
        """The degradation provenance item ``index`` records (``[{name, params, seed, preset}, …]``,
        every part of a mixture with its parameters), computed without rendering (a chain whose
        presets scale with the scene reads its Gaussians for the scene depth,
        :func:`~spacedg.data.pipeline.sample_scene_depth`)."""

        record, chain, name = self.plan(index)
        parsed = Chain.parse(chain)
        depth = None
        if parsed.scales_with_depth(self.options.default_preset, self.options.mixture_preset):
            depth = sample_scene_depth(self._scene(record.scene_id), record.views)
        return parsed.provenance(self._sample_seed(record, name), self.options.default_preset, self.options.mixture_preset, depth)

    # ------------------------------------------------------------ items
    def _cache(self) -> ByteLRU:
        """This worker's cache: scenes (sized by their Gaussians) and clean renders (by their arrays)."""
        if self._scenes is None:
            def size_of(value: Any) -> int:
                return frames_nbytes(value) if isinstance(value, list) else value.gaussians.nbytes

            self._scenes = ByteLRU(self._cache_bytes, size_of)
        return self._scenes

    def _scene(self, scene_id: str) -> Any:
        folder = self.scene_dirs[scene_id]
        return self._cache().get(("scene", scene_id), lambda: load_scene(folder))

    def _set_worker_threads(self) -> None:
        """In a DataLoader worker, once: numba threads = ``render_threads`` as given, else the
        plan's for the DataLoader's actual worker count."""
        self._threads_set = True
        info = torch.utils.data.get_worker_info()
        if info is not None:
            from spacedg.render.threads import set_render_threads

            threads = self.render_threads if self._threads_given else loader_plan(workers=info.num_workers).render_threads
            set_render_threads(threads)

    def __getitem__(self, index: int) -> dict[str, Any]:
        if not self._threads_set:
            self._set_worker_threads()
        item = self._item(index)
        if self.defer_render:
            return item
        return self._render_item(item)

    def _render_item(self, item: dict[str, Any]) -> dict[str, Any]:
        if self._on_device:
            from torch.utils.data import get_worker_info

            if get_worker_info() is not None:
                raise ParameterError(
                    f"SpaceDGDataset(device={self.options.device!r}) renders on the GPU in the process that owns it, not in "
                    "DataLoader worker processes: use num_workers=0, or SpaceDGDataset(..., defer_render=True) with "
                    "DataLoader(..., collate_fn=list) and render each batch in the main process with dataset.render_batch(batch)"
                )
        record, chain, name = self.plan(item["index"])
        scene = self._scene(record.scene_id)
        result = degrade(scene, record.views, chain, seed=self._sample_seed(record, name), options=self.options, render_cache=self._cache())
        images = torch.from_numpy(np.ascontiguousarray(result.images.transpose(0, 3, 1, 2)))
        return {"images": images, **item, "degradation": result.degradations, "stats": dict(result.stats)}

    def render_batch(self, items: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
        """Render items returned with ``defer_render=True`` (in this process: the one owning the GPU).

        Items are rendered one after another (a sample's chains share their render); each comes
        back with ``images``, ``degradation`` (provenance) and ``stats``: the same item
        ``dataset[index]`` gives without deferral (same epoch).
        """
        if isinstance(items, dict):
            raise ParameterError("render_batch takes a list of items; build the DataLoader with collate_fn=list")
        return [item if "images" in item else self._render_item(item) for item in items]

    def _item(self, index: int) -> dict[str, Any]:
        """Item ``index`` without its images (no rendering)."""
        record, chain, name = self.plan(index)
        return {
            "question": record.question,
            "options": list(record.options),
            "answer": list(record.answer) if isinstance(record.answer, tuple) else record.answer,
            "question_type": record.question_type,
            "sub_question_type": record.sub_question_type,
            "task_group": record.task_group.value,
            "answer_type": record.answer_type.value,
            "degradation_type": name,
            "scene_id": record.scene_id,
            "views": list(record.views),
            "record_id": record.id,
            "index": int(index),
        }

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_scenes"] = None  # each worker builds its own cache
        state["_threads_set"] = False  # and sets its own thread count
        return state


def _spread_subset(records: list[QARecord], n: int, seed: int) -> list[QARecord]:
    """At most ``n`` records, taken round-robin over question types (each type's records in a
    seeded order), returned in their original order."""
    if n < 1:
        raise ParameterError(f"SpaceDGDataset: max_questions must be >= 1, got {n}")
    rng = np.random.default_rng(seed)
    by_type: dict[str, list[int]] = {}
    for i, record in enumerate(records):
        by_type.setdefault(record.question_type, []).append(i)
    queues = [[ix[j] for j in rng.permutation(len(ix))] for _, ix in sorted(by_type.items())]
    taken: list[int] = []
    while len(taken) < n and any(queues):
        for queue in queues:
            if queue and len(taken) < n:
                taken.append(queue.pop())
    return [records[i] for i in sorted(taken)]

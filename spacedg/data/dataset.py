"""``SpaceDGDataset``: degraded multi-view question samples rendered online, for PyTorch.

A map-style :class:`torch.utils.data.Dataset`. Its length and every item are a pure function of
the arguments (the seed, the scenes and their question indexes), whatever process or worker
renders them.

- **Scenes**: native scene folders (``scenes=[...]``), or by default the built-in procedural
  rooms (:func:`~spacedg.scene.store.builtin_scene_dirs`, generated on first use). Each
  scene goes to one split (:func:`~spacedg.scene.store.assign_splits`), so ``train``,
  ``val`` and ``bench`` never share a scene.
- **Questions**: each scene's question index (:mod:`spacedg.qa.build`, :mod:`spacedg.qa.index`), built on first use
  in a *spawned* process; optionally restricted to ``families``.
- **Degradations**:
  - ``train`` / ``val``: one item per question. The item is clean with probability
    ``clean_prob``, otherwise one chain drawn uniformly from ``degradations``. Names without a
    preset take ``severity``, which is ``"bench"`` (the paper's table), ``"1"``–``"5"``, or
    ``"random"`` (a seeded severity per item); mixtures keep their own recipe.
    :meth:`set_epoch` redraws the choices per epoch (shared memory, so persistent workers see it).
  - ``bench``: every question under clean and under each chain of ``degradations`` (default:
    the paper's nine at ``bench``), i.e. ``questions × 10`` items.
  - ``degradations`` also accepts ``"all"`` (every registered degradation, third-party
    included), mixture recipes (``"night_capture"``), presets (``"haze:3"``), chains
    (``"haze+low_res"``) and mappings with explicit parameters (``{"name": "haze", "params":
    {"density": 3.5}}``).
- **Plans**: :meth:`SpaceDGDataset.plan` decides an item once (record, frozen
  :class:`~spacedg.data.chain.Chain`, sample seed: an :class:`~spacedg.data.pipeline.ItemPlan`) and
  the pipeline renders that object (:func:`~spacedg.data.pipeline.degrade_plan`); the chain is never
  turned into text and parsed again on the way.
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
  then return items without ``images`` (question text and the item's ``plan``) and the main process
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
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch.utils.data import Dataset

from spacedg._checks import (
    check_bool,
    check_choice,
    check_fractions,
    check_image_size,
    check_int,
    check_names,
    check_number,
    short_repr,
)
from spacedg.data.chain import BENCH_DEGRADATIONS, SEVERITIES, Chain, DegradationChoice
from spacedg.data.pipeline import (
    ItemPlan,
    PipelineOptions,
    degrade_plan,
    frames_nbytes,
    sample_image_size,
    sample_scene_depth,
)
from spacedg.data.view_depths import ensure_view_depths
from spacedg.qa.build import ensure_indexes
from spacedg.qa.index import QABuildConfig, config_index_paths, read_index
from spacedg.data.workers import loader_plan
from spacedg.devices import resolve_device
from spacedg.errors import InvalidDataError, ParameterError
from spacedg.limits import check_image_size as check_size_limit
from spacedg.plugins.qa_record import QARecord
from spacedg.plugins.registry import get_question_family, list_degradations
from spacedg.render.renderer import BACKENDS
from spacedg.scene.io import load_scene
from spacedg.scene.store import (
    SPLITS,
    ByteLRU,
    assign_splits,
    builtin_scene_dirs,
    scene_dirs_of,
)
from spacedg.seeding import derive_seed

__all__ = ["ItemPlan", "SpaceDGDataset"]

_SEVERITIES = (*SEVERITIES, "random")
_WHERE = "SpaceDGDataset"


class SpaceDGDataset(Dataset):
    """Online degraded SpaceDG samples (see the module docstring).

    Every argument is checked at the call: a bad one raises a
    :class:`~spacedg.errors.ParameterError` (an unknown degradation or family an
    :class:`~spacedg.errors.UnknownPluginError`) naming it, before any scene is read.

    Args:
        split: ``"train"``, ``"val"`` or ``"bench"``.
        degradations: one chain or a list of chains, each any form :class:`~spacedg.data.chain.Chain`
            reads (names, ``name:preset``, mixtures, ``a+b``, ``{"name", "preset", "params"}`` mappings,
            ``Chain`` objects), or ``"all"``; ``None`` means the nine paper degradations for ``bench``
            and clean only for ``train``/``val``.
        scenes: a scene folder or a list of them (or of folders of them); default: the built-in rooms.
        families: keep only these question families (default: all).
        question_types: the old name of ``families`` (deprecated; kept for one release).
        severity: preset for chains named without one: ``"bench"``, ``"1"``–``"5"`` or ``"random"``.
        clean_prob: probability of a clean item in ``train``/``val`` (ignored by ``bench``).
        image_size: ``(width, height)`` pixels, a bounding box, or ``None`` for the views' own size:
            each view renders at the largest size of its own aspect ratio within the box (a 16:9 view
            at ``(320, 240)`` is 320×180, a 4:3 one 320×240; intrinsics scaled, nothing cropped or
            squeezed: :meth:`~spacedg.render.camera.Camera.fitted`). Items of captures of different
            aspect ratios therefore have different shapes (``collate_fn=list`` keeps them apart).
        seed: seed of the degradation choices and their noise (not of the splits or questions).
        cache: byte budget of each worker's LRU cache of scenes (their Gaussians) and clean
            renders (shared by every chain without a raster step), default 2 GiB.
        qa_config: how the question indexes are built (default: ``QABuildConfig()``, seed 0:
            each scene's full index ``<scene id>.qa.jsonl``, shared by every dataset over the
            same folders; a config naming ``families`` reads that selection's own index file,
            :func:`~spacedg.qa.index.index_paths`).
        split_fractions: ``(val, bench)`` share of scenes; ``(0, 1)`` puts every scene (even one) in
            ``bench`` (see :func:`~spacedg.scene.store.assign_splits`).
        split_seed: seed of the scene → split assignment (kept apart from ``seed`` so that
            changing the augmentation seed never moves a scene between splits).
        on_bad_scene: ``"raise"`` (default) or ``"skip"`` a scene that cannot be read or indexed
            (skipped scenes are named in a warning and in :attr:`skipped`).
        backend: renderer backend (``"auto"``, ``"cpu"``, ``"torch"``, ``"gsplat"``).
        device: torch device (:func:`spacedg.devices.resolve_device`); a non-CPU device renders and degrades
            there, in the main process only (module docstring).
        defer_render: items come without ``images``, ``degradation`` and ``stats`` but with their ``plan``
            (:class:`~spacedg.data.pipeline.ItemPlan`); :meth:`render_batch` renders them, in the process that owns the GPU.
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
        scenes: str | os.PathLike[str] | Sequence[str | os.PathLike[str]] | None = None,
        families: Sequence[str] | None = None,
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
        self.split = check_choice(split, f"{_WHERE}: split", SPLITS)
        self.severity = check_choice(severity, f"{_WHERE}: severity", _SEVERITIES)
        self.clean_prob = check_number(clean_prob, f"{_WHERE}: clean_prob", low=0.0, high=1.0)
        self.seed = check_int(seed, f"{_WHERE}: seed")
        check_choice(on_bad_scene, f"{_WHERE}: on_bad_scene", ("raise", "skip"))
        fractions = check_fractions(split_fractions, f"{_WHERE}: split_fractions")
        split_seed = check_int(split_seed, f"{_WHERE}: split_seed")
        wanted = _families(families, question_types)
        if max_questions is not None:
            max_questions = check_int(max_questions, f"{_WHERE}: max_questions", minimum=1)
        self._cache_bytes = check_int(cache, f"{_WHERE}: cache (bytes)", minimum=0)
        self.defer_render = check_bool(defer_render, f"{_WHERE}: defer_render")
        if qa_config is not None and not isinstance(qa_config, QABuildConfig):
            raise ParameterError(f"{_WHERE}: qa_config must be a QABuildConfig or None, got {short_repr(qa_config)}")
        self.qa_config = qa_config or QABuildConfig()
        resolve_device(device, f"{_WHERE}: device")  # malformed, CUDA without CUDA, a missing index: now
        size = check_image_size(image_size, f"{_WHERE}: image_size")
        if size is not None:
            check_size_limit(*size, f"{_WHERE}: image_size", "render smaller", ParameterError)
        self.options = PipelineOptions(image_size=size, backend=check_choice(backend, f"{_WHERE}: backend", BACKENDS), device=device)
        plan = loader_plan(workers=_optional_count(workers, "workers", 0), render_threads=_optional_count(render_threads, "render_threads", 1))
        #: DataLoader workers suggested for this dataset and numba threads per worker (see spacedg.data.workers).
        self.workers, self.render_threads = plan.workers, plan.render_threads
        self._threads_given = render_threads is not None
        self._threads_set = False
        self._on_device = device is not None and str(device) != "cpu" and not str(device).startswith("cpu:")
        #: The chains of this dataset (frozen :class:`~spacedg.data.chain.Chain` objects, severity applied).
        self.chains: list[Chain]
        # _reads_depth: some chain reads the scene depth (scenes then come with their views' depths)
        self.chains, self._reads_depth = self._chains(degradations)
        dirs = _scene_dirs(scenes, builtin_rooms)
        self._load(dirs, on_bad_scene, fractions, split_seed, wanted)
        if max_questions is not None:
            self.records = _spread_subset(self.records, max_questions, derive_seed(split_seed, "subset", self.split))
        # shared memory: set_epoch() in the main process reaches persistent DataLoader workers
        self._epoch = torch.zeros((), dtype=torch.int64).share_memory_()
        self._scenes: ByteLRU | None = None  # created lazily in each worker

    # ------------------------------------------------------------ construction
    def _load(self, dirs: list[Path], on_bad_scene: str, fractions: tuple[float, float], split_seed: int,
              wanted: set[str] | None) -> None:
        """Build missing question indexes, assign scenes to splits and keep this split's records."""
        self.skipped: dict[str, str] = {}
        failed = ensure_indexes(dirs, self.qa_config)
        if failed:
            listing = "; ".join(f"{d}: {e}" for d, e in failed.items())
            if on_bad_scene == "raise":
                raise InvalidDataError(f"{len(failed)} scene(s) cannot be used: {listing}. Fix or remove them, or pass on_bad_scene='skip'")
            warnings.warn(f"SpaceDGDataset: skipping {len(failed)} scene(s): {listing}", stacklevel=3)
            self.skipped = dict(failed)
        all_dirs = list(dirs)
        dirs = [d for d in dirs if str(d) not in failed]
        records_by_dir = {d: self._records(d) for d in dirs}
        ids = {d: recs[0].scene_id if recs else d.name for d, recs in records_by_dir.items()}
        # skipped scenes keep their place in the assignment, so skipping never moves another scene
        every_id = [ids.get(d, d.name) for d in all_dirs]
        splits = assign_splits(every_id, fractions, seed=split_seed)
        self.scene_splits: dict[str, str] = dict(splits)  # every scene id → its split (what went where)
        self.scene_dirs: dict[str, Path] = {ids[d]: d for d in dirs if splits[ids[d]] == self.split}
        self.records: list[QARecord] = [
            r for d in dirs if splits[ids[d]] == self.split for r in records_by_dir[d] if wanted is None or r.question_type in wanted
        ]

    def _chains(self, degradations: Any) -> tuple[list[Chain], bool]:
        """The dataset's chains, severity applied, and whether resolving one reads the scene depth at some severity
        an item can draw; unknown names, presets and repeats fail here, with suggestions."""
        if degradations is None:
            items: list[Any] = list(BENCH_DEGRADATIONS) if self.split == "bench" else []
        elif isinstance(degradations, str) and degradations == "all":
            items = [spec.name for spec in list_degradations()]
        elif isinstance(degradations, (str, Chain, DegradationChoice, Mapping)):
            items = [degradations]  # one chain
        elif isinstance(degradations, (list, tuple)):
            items = list(degradations)
        else:
            raise ParameterError(
                f"{_WHERE}: degradations must be a chain ('haze', 'haze:3+low_res', 'night_capture', "
                f"{{'name': 'haze', 'params': {{...}}}}), a list of chains, 'all' or None; got {short_repr(degradations)}"
            )
        random_levels = self.severity == "random" and self.split != "bench"
        levels = SEVERITIES[1:] if random_levels else (None,)
        chains = []
        reads_depth = False
        for item in items:
            chain = Chain.parse(item)
            if self.severity != "random":
                chain = chain.with_severity(self.severity)
            variants = [chain if level is None else chain.with_severity(level) for level in levels]
            for variant in variants:
                variant.check()
            reads_depth = reads_depth or any(v.scales_with_depth(self.options.default_preset, self.options.mixture_preset) for v in variants)
            chains.append(chain)
        if len(set(chains)) != len(chains):
            raise ParameterError(f"{_WHERE}: degradations repeat a chain: {[c.text for c in chains]}")
        return chains, reads_depth

    def _records(self, folder: Path) -> list[QARecord]:
        jsonl, _ = config_index_paths(load_scene(folder).id, folder, self.qa_config)
        return read_index(jsonl)

    # ------------------------------------------------------------ indexing
    def __len__(self) -> int:
        return len(self.records) * (len(self.chains) + 1 if self.split == "bench" else 1)

    @property
    def epoch(self) -> int:
        return int(self._epoch)

    def set_epoch(self, epoch: int) -> None:
        """Redraw the train/val degradation choices for ``epoch`` (like ``DistributedSampler.set_epoch``);
        the value lives in shared memory, so persistent DataLoader workers see it too."""
        self._epoch.fill_(int(check_number(epoch, f"{_WHERE}.set_epoch: epoch", low=0)))

    def plan(self, index: int) -> ItemPlan:
        """What item ``index`` renders (no rendering): its record, its :class:`~spacedg.data.chain.Chain`
        (empty for a clean item) and its sample seed, as an :class:`~spacedg.data.pipeline.ItemPlan`."""
        if isinstance(index, bool) or not isinstance(index, (int, np.integer)):
            raise TypeError(f"SpaceDGDataset indices must be integers, got {type(index).__name__}")
        index = int(index)
        if not 0 <= index < len(self):
            raise IndexError(f"SpaceDGDataset index {index} out of range [0, {len(self)})")
        chain = Chain()
        if self.split == "bench":
            record = self.records[index // (len(self.chains) + 1)]
            k = index % (len(self.chains) + 1)
            if k:
                chain = self.chains[k - 1]
        else:
            record = self.records[index]
            rng = np.random.default_rng(derive_seed(self.seed, "choice", self.epoch, record.id))
            if self.chains and not rng.random() < self.clean_prob:
                chain = self.chains[int(rng.integers(len(self.chains)))]
                if self.severity == "random":
                    chain = chain.with_severity(str(int(rng.integers(1, 6))))
        seed = derive_seed(self.seed, "sample", record.id, chain.name, self.epoch if self.split != "bench" else 0)
        return ItemPlan(index, record, chain, seed)

    def provenance(self, index: int) -> list[dict[str, Any]]:
        """The degradation provenance item ``index`` records (``[{name, params, seed, preset}, …]``,
        every part of a mixture with its parameters), computed without rendering (a chain whose
        presets scale with the scene reads its Gaussians for the scene depth,
        :func:`~spacedg.data.pipeline.sample_scene_depth`)."""
        plan = self.plan(index)
        depth = None
        if plan.chain.scales_with_depth(self.options.default_preset, self.options.mixture_preset):
            depth = sample_scene_depth(self.scene(plan.record.scene_id), plan.views)
        size = None if plan.chain.is_clean else sample_image_size(self.scene(plan.record.scene_id), plan.views, self.options)
        return plan.chain.provenance(plan.seed, self.options.default_preset, self.options.mixture_preset, depth, size)

    # ------------------------------------------------------------ items
    def _cache(self) -> ByteLRU:
        """This worker's cache: scenes (sized by their Gaussians) and clean renders (by their arrays)."""
        if self._scenes is None:
            def size_of(value: Any) -> int:
                return frames_nbytes(value) if isinstance(value, list) else value.gaussians.nbytes

            self._scenes = ByteLRU(self._cache_bytes, size_of)
        return self._scenes

    def scene(self, scene_id: str) -> Any:
        """The loaded :class:`~spacedg.scene.Scene` of ``scene_id``, kept in the dataset's byte-bounded cache.
        When a chain reads the scene depth, its views' depths come with it, from the table in the scene
        folder or measured once for the whole scene and written there (:mod:`spacedg.data.view_depths`)."""
        folder = self.scene_dirs[scene_id]
        return self._cache().get(("scene", scene_id), lambda: self._load_scene(folder))

    def _load_scene(self, folder: Path) -> Any:
        scene = load_scene(folder)
        if self._reads_depth:
            ensure_view_depths(scene, folder)
        return scene

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
        return self.sample(self.plan(index))

    def sample(self, plan: ItemPlan) -> dict[str, Any]:
        """The item of ``plan`` (:meth:`plan`): ``dataset[index]`` is ``dataset.sample(dataset.plan(index))``."""
        if not self._threads_set:
            self._set_worker_threads()
        item = self._item(plan)
        if self.defer_render:
            return {**item, "plan": plan}  # the plan travels with the item to render_batch (no second plan())
        return self._render_item(item, plan)

    def _render_item(self, item: dict[str, Any], plan: ItemPlan) -> dict[str, Any]:
        if self._on_device:
            from torch.utils.data import get_worker_info

            if get_worker_info() is not None:
                raise ParameterError(
                    f"SpaceDGDataset(device={self.options.device!r}) renders on the GPU in the process that owns it, not in "
                    "DataLoader worker processes: use num_workers=0, or SpaceDGDataset(..., defer_render=True) with "
                    "DataLoader(..., collate_fn=list) and render each batch in the main process with dataset.render_batch(batch)"
                )
        scene = self.scene(plan.record.scene_id)
        result = degrade_plan(scene, plan, self.options, render_cache=self._cache())
        images = torch.from_numpy(np.ascontiguousarray(result.images.transpose(0, 3, 1, 2)))
        return {"images": images, **item, "degradation": result.degradations, "stats": dict(result.stats)}

    def render_batch(self, items: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
        """Render items returned with ``defer_render=True`` (in this process: the one owning the GPU).

        Items are rendered one after another (a sample's chains share their render), each from the
        :class:`~spacedg.data.pipeline.ItemPlan` it carries (``item["plan"]``, made where the item was
        planned, e.g. a DataLoader worker); each comes back with ``images``, ``degradation``
        (provenance) and ``stats`` and without ``plan``: the same item ``dataset[index]`` gives
        without deferral (same epoch).
        """
        if isinstance(items, dict) or not isinstance(items, (list, tuple)):
            raise ParameterError(f"render_batch takes a list of items; build the DataLoader with collate_fn=list (got {short_repr(items)})")
        out = []
        for item in items:
            if "images" in item:
                out.append(item)
                continue
            fields = {k: v for k, v in item.items() if k != "plan"}
            plan = item.get("plan")
            out.append(self._render_item(fields, plan if isinstance(plan, ItemPlan) else self.plan(fields["index"])))
        return out

    def _item(self, plan: ItemPlan) -> dict[str, Any]:
        """The item of ``plan`` without its images (no rendering)."""
        record = plan.record
        return {
            "question": record.question,
            "options": list(record.options),
            "answer": list(record.answer) if isinstance(record.answer, tuple) else record.answer,
            "question_type": record.question_type,
            "sub_question_type": record.sub_question_type,
            "task_group": record.task_group.value,
            "answer_type": record.answer_type.value,
            "degradation_type": plan.degradation_type,
            "scene_id": record.scene_id,
            "views": list(record.views),
            "record_id": record.id,
            "index": plan.index,
        }

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_scenes"] = None  # each worker builds its own cache
        state["_threads_set"] = False  # and sets its own thread count
        return state


def _optional_count(value: Any, name: str, minimum: int) -> int | None:
    return None if value is None else check_int(value, f"{_WHERE}: {name}", minimum=minimum)


def _families(families: Any, question_types: Any) -> set[str] | None:
    """The question families to keep (``None``: all); ``question_types`` is the deprecated name."""
    if question_types is not None:
        if families is not None:
            raise ParameterError(f"{_WHERE}: give families= only (question_types= is its old name), not both")
        warnings.warn(f"{_WHERE}: question_types= is deprecated, use families= (the same names)", DeprecationWarning, stacklevel=3)
        families = question_types
    if families is None:
        return None
    names = check_names(families, f"{_WHERE}: families")
    return {get_question_family(name).name for name in names}  # unknown names fail with suggestions


def _scene_dirs(scenes: Any, builtin_rooms: Any) -> list[Path]:
    """Scene folders of ``scenes`` (a path or a list of paths), or of the built-in rooms when ``None``."""
    if scenes is None:
        return builtin_scene_dirs(check_int(builtin_rooms, f"{_WHERE}: builtin_rooms", minimum=3))
    if isinstance(scenes, (str, os.PathLike)):
        scenes = [scenes]
    if not isinstance(scenes, (list, tuple)) or not scenes or not all(isinstance(p, (str, os.PathLike)) for p in scenes):
        raise ParameterError(f"{_WHERE}: scenes must be a scene folder or a non-empty list of folders (paths), got {short_repr(scenes)}")
    return scene_dirs_of(scenes)


def _spread_subset(records: list[QARecord], n: int, seed: int) -> list[QARecord]:
    """At most ``n`` records, taken round-robin over question types (each type's records in a
    seeded order), returned in their original order."""
    if n < 1:
        raise ParameterError(f"SpaceDGDataset: max_questions must be >= 1, got {n}")
    rng = np.random.default_rng(seed)
    by_type: dict[str, list[int]] = {}
    for i, record in enumerate(records):
        by_type.setdefault(record.question_type, []).append(i)
    queues = {t: [ix[j] for j in rng.permutation(len(ix))] for t, ix in sorted(by_type.items())}
    shares = round_robin_shares({t: len(q) for t, q in queues.items()}, n)
    taken = [i for t, q in queues.items() for i in q[len(q) - shares[t]:]]  # each queue's last ``share``: what popping round-robin takes
    return [records[i] for i in sorted(taken)]


def round_robin_shares(available: Mapping[str, int], total: int) -> dict[str, int]:
    """``total`` shared over the keys one at a time in sorted order, each at most its ``available``:
    how many records taking them round-robin over the keys gives each (``--max-questions`` over question types)."""
    shares = dict.fromkeys(sorted(available), 0)
    left = min(total, sum(available.values()))
    while left > 0:
        for key in shares:
            if left > 0 and shares[key] < available[key]:
                shares[key] += 1
                left -= 1
    return shares

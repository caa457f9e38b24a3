"""The ``data`` config group: what trains (online SpaceDG samples or an exported chat JSONL) and
what evaluates (``val`` items).

``conf/data/online.yaml`` is instantiated (:func:`spacedg.sft.config.build`) into a
:class:`DataOptions` holding a :class:`ValOptions`. Neither declares defaults: the YAML holds each
one, once. Building the options checks them, degradation chains included (with
:class:`~spacedg.data.chain.Chain`, as :class:`~spacedg.data.dataset.SpaceDGDataset` will), so an
unknown name or preset fails before any model loads or any question index is built.

Conventions of the config that differ from :class:`~spacedg.data.dataset.SpaceDGDataset`:
``degradations: null`` means the paper's nine (:data:`~spacedg.data.chain.BENCH_DEGRADATIONS`) for
training and evaluation alike (the dataset's own ``None`` means clean only for ``train``/``val``);
``max_questions`` caps the training questions only; ``val`` renders the ``val`` split (scenes apart
from the training ones) with the training ``scenes``, ``builtin_rooms``, ``image_size``,
``severity`` and ``seed`` -- whatever the training source: with ``source: jsonl`` the evaluation
still renders the ``val`` split of ``scenes`` (the built-in rooms when null); ``val.samples: 0``
turns it off. ``render_device: cuda`` renders and degrades the online samples on each rank's own
GPU (``cuda:$LOCAL_RANK``) in the training process (``train.dataloader_num_workers`` must then
be 0: CUDA stays in the process that owns it); ``null`` renders on the CPU in DataLoader workers.
``qa_mode`` picks the question index of the training split (``train``: the dense train selection,
more questions per scene; ``bench``: the strict one; ``null``: the dataset's default), passed to
the dataset as ``qa_config=QABuildConfig(mode=...)`` (:func:`qa_config_for`); evaluation reads the default.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from spacedg._checks import check_int
from spacedg.data.chain import BENCH_DEGRADATIONS, SEVERITIES, Chain
from spacedg.data.chat import chat_messages, item_images
from spacedg.data.public_format import public_fields
from spacedg.data.dataset import SpaceDGDataset
from spacedg.errors import ParameterError, error_context
from spacedg.qa import index as qa_index
from spacedg.sft.data import ChatJsonlDataset, OnlineSFTDataset

__all__ = ["DataOptions", "QA_MODES", "ValOptions", "qa_config_for"]

_SEVERITIES = (*SEVERITIES, "random")

#: A ``degradations`` value: null (the nine), ``"all"``, one chain or a list of chains.
Degradations = str | Sequence[Any] | None


def _check_degradations(degradations: Degradations, severity: str, where: str) -> None:
    """Parse and resolve each chain of ``degradations`` with :meth:`Chain.check` at every severity
    it can be drawn at (``"random"``: ``"1"``–``"5"``), so unknown names, presets and repeats raise
    now, their message prefixed with ``where`` (the config key). ``None`` (the nine) and ``"all"``
    (every registered degradation) need no check."""
    if degradations is None or degradations == "all":
        return
    levels = SEVERITIES[1:] if severity == "random" else (severity,)
    with error_context(where):
        for chain in [degradations] if isinstance(degradations, str) else degradations:
            Chain.parse(chain).check(levels)


#: The question-index selection modes ``data.qa_mode`` accepts.
QA_MODES: tuple[str, ...] = qa_index.MODES


def qa_config_for(mode: str | None) -> qa_index.QABuildConfig | None:
    """The :class:`~spacedg.qa.index.QABuildConfig` whose index trains for ``data.qa_mode``: ``None``
    (the dataset's default) for ``None``."""
    if mode is None:
        return None
    return qa_index.QABuildConfig(mode=mode)


@dataclass(frozen=True)
class ValOptions:
    """The ``data.val`` node: generation-based evaluation on the ``val`` split.

    ``samples``: items per evaluation (0: none); ``degradations`` / ``clean_prob``: the mixture of
    those items (as in :class:`DataOptions`); ``max_new_tokens`` / ``batch_size``: greedy generation.
    """

    samples: int
    degradations: Degradations
    clean_prob: float
    max_new_tokens: int
    batch_size: int

    def __post_init__(self) -> None:
        for name, least in (("samples", 0), ("max_new_tokens", 1), ("batch_size", 1)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < least:
                raise ParameterError(f"data.val.{name} must be an integer >= {least}, got {value!r}")


@dataclass(frozen=True)
class DataOptions:
    """The ``data`` group (keys documented in ``conf/data/online.yaml``); validated on construction.

    ``image_size`` is ``[width, height]`` in pixels (``None``: each view's own size);
    ``max_length`` is the token budget per sample (longer samples are dropped, never truncated).
    """

    source: Literal["online", "jsonl"]
    jsonl: str | None
    scenes: Sequence[str] | None
    builtin_rooms: int
    image_size: Sequence[int] | None
    degradations: Degradations
    clean_prob: float
    severity: str
    question_types: Sequence[str] | None
    max_questions: int | None
    qa_mode: str | None
    seed: int
    max_length: int
    render_device: str | None
    val: ValOptions

    def __post_init__(self) -> None:
        if self.source not in ("online", "jsonl"):
            raise ParameterError(f"data.source must be online or jsonl, got {self.source!r}")
        if self.source == "jsonl" and not self.jsonl:
            raise ParameterError("data.source=jsonl needs data.jsonl=PATH (a chat .jsonl written by spacedg export)")
        if self.qa_mode is not None and self.qa_mode not in QA_MODES:
            raise ParameterError(f"data.qa_mode must be null or one of {list(QA_MODES)}, got {self.qa_mode!r}")
        if self.severity not in _SEVERITIES:
            raise ParameterError(f"data.severity must be one of {list(_SEVERITIES)}, got {self.severity!r}")
        if self.source == "online":
            _check_degradations(self.degradations, self.severity, "data.degradations")
        if self.val.samples > 0:
            _check_degradations(self.val.degradations, self.severity, "data.val.degradations")

    def _dataset(self, split: str, degradations: Degradations, clean_prob: float, max_questions: int | None) -> SpaceDGDataset:
        return SpaceDGDataset(
            split, list(BENCH_DEGRADATIONS) if degradations is None else degradations, scenes=self.scenes,
            families=self.question_types, severity=self.severity, clean_prob=clean_prob,
            image_size=self.image_size, seed=self.seed, max_questions=max_questions, builtin_rooms=self.builtin_rooms,
            device=self.rank_render_device(), qa_config=qa_config_for(self.qa_mode) if split == "train" else None,
        )

    def rank_render_device(self) -> str | None:
        """``render_device`` for this process: ``"cuda"`` becomes ``cuda:$LOCAL_RANK`` (each rank renders on its own GPU)."""
        if self.render_device in (None, "cpu"):
            return None
        if self.render_device == "cuda":
            return f"cuda:{int(os.environ.get('LOCAL_RANK', '0'))}"
        return str(self.render_device)

    def train_data(self) -> OnlineSFTDataset | ChatJsonlDataset:
        """The unbudgeted training samples: the ``train`` split rendered online, or the JSONL's."""
        if self.source == "jsonl":
            return ChatJsonlDataset(self.jsonl)
        return OnlineSFTDataset(self._dataset("train", self.degradations, self.clean_prob, self.max_questions))

    def val_dataset(self) -> SpaceDGDataset | None:
        """The ``val`` split the evaluation draws from (whatever the training source); ``None``
        without evaluation (``val.samples`` 0)."""
        if self.val.samples <= 0:
            return None
        return self._dataset("val", self.val.degradations, self.val.clean_prob, None)

    def val_description(self) -> str:
        """One line saying what the evaluation renders (recorded in ``train_summary.json``)."""
        if self.val.samples <= 0:
            return "none (data.val.samples=0)"
        return f"{self.val.samples} items of the val split of {self.scenes_description()}, rendered online"

    def scenes_description(self) -> str:
        """What the datasets read, in words: the scenes under ``data.scenes`` or the built-in rooms."""
        return f"the scenes under data.scenes ({len(self.scenes)} path(s))" if self.scenes else f"{self.builtin_rooms} built-in rooms"

    def val_items(self, rank: int = 0, world: int = 1, dataset: SpaceDGDataset | None = None) -> list[dict[str, Any]]:
        """``val.samples`` items of the ``val`` split (a spread drawn with ``seed``), rendered once,
        each with its prompt (no answer), images, condition and the fields the scorer reads.

        ``rank`` of ``world`` processes: only that process's share, every ``world``-th item of the
        spread in index order from the ``rank``-th (the items it answers; all of them by default).
        ``dataset``: :meth:`val_dataset`, built before (default: built here)."""
        world = check_int(world, "val_items: world", minimum=1)
        rank = check_int(rank, "val_items: rank", minimum=0, maximum=world - 1)
        dataset = self.val_dataset() if dataset is None else dataset
        if dataset is None:
            return []
        order = np.random.default_rng(self.seed).permutation(len(dataset))[:self.val.samples]
        items = []
        for index in sorted(int(i) for i in order)[rank::world]:
            item = dataset[index]
            images = item_images(item)
            fields = public_fields(item)  # asked and scored in the bench's form
            conversation = chat_messages(fields["question"], len(images))
            truth = {k: fields[k] for k in ("answer", "answer_type", "question_type", "sub_question_type")}
            truth["options"] = {line[0]: line[3:] for line in fields["options"]}
            items.append({"conversation": conversation, "images": images, "degradation_type": item["degradation_type"],
                          "truth": truth})
        return items

"""Blind pruning of a bench dataset before export (``spacedg export --split bench``: on by default, ``--no-debias`` skips it).

The export builds its question indexes with :data:`~spacedg.qa.debias.OVERSAMPLE` × ``--per-sub-type``
records per sub type and scene (``partial_rounds``: its balancing cells take partial rounds too,
``<id>.qa-pooled.jsonl``; with ``--max-questions N`` it keeps every candidate, and the pruning's
trim takes the bench to ``N`` (:func:`bench_targets`), keeping every cell's roles balanced), then
:func:`debias_dataset` pools the bench's records over all its scenes, balances every cell's roles
across them (:func:`~spacedg.qa.cell_balance.balance_cells`), prunes
what the blind models solve (:func:`spacedg.qa.debias.debias`) and trims every sub type to what
the bench asks for (:func:`bench_targets`: ``--per-sub-type`` per scene, or ``--max-questions``
shared as a bench without pruning shares it), so the pruned bench keeps its requested size
wherever the candidates allow (a sub type that whole rounds left short, such as the size
comparisons, can come out larger than the same bench without pruning: partial rounds complete
each other across scenes). The result is a pure function of the records and
the seed: every shard of a sharded export prunes the same way. A bench of fewer than
:data:`MIN_SCENES` scenes is not pruned (nothing can be held out), nor oversampled:
:func:`bench_scene_count` tells the export before it builds any index.

Written beside the export: ``debias.json`` (:meth:`~spacedg.qa.debias.DebiasResult.to_dict`:
before/after per sub type, records removed per round and sub type) and ``debias.md``
(:func:`~spacedg.qa.debias.format_debias`).
"""

from __future__ import annotations

import json
from collections import Counter
from collections.abc import Sequence
from pathlib import Path

from spacedg.data.dataset import SpaceDGDataset, round_robin_shares
from spacedg.files import atomic_write_bytes
from spacedg.plugins.qa_record import QARecord
from spacedg.qa.debias import OVERSAMPLE, DebiasResult, debias_pooled, format_debias, spread_targets

__all__ = ["MIN_SCENES", "OVERSAMPLE", "bench_scene_count", "bench_targets", "debias_dataset", "write_debias_report"]

#: Scenes a bench needs for the blind pruning (the probe holds whole scenes out).
MIN_SCENES = 2


def bench_scene_count(n_scenes: int, fractions: tuple[float, float]) -> int:
    """How many of ``n_scenes`` scenes :func:`~spacedg.scene.store.assign_splits` puts in the bench
    (it depends on the count alone, not on the scene ids); 0 when the scenes cannot be split."""
    from spacedg.errors import InvalidDataError
    from spacedg.scene.store import assign_splits

    try:
        splits = assign_splits([f"s{i}" for i in range(n_scenes)], fractions)
    except InvalidDataError:
        return 0
    return sum(1 for split in splits.values() if split == "bench")


def bench_targets(records: Sequence[QARecord], per_sub_type: int, max_questions: int | None = None) -> dict[tuple[str, str], int]:
    """Records wanted per ``(question_type, sub_question_type)`` from oversampled candidates:
    per scene at most ``per_sub_type`` of each (what a bench at ``per_sub_type`` asks for),
    summed over scenes; with ``max_questions``, that many in all, shared over question types
    round-robin as ``--max-questions`` shares a bench without pruning (a type with fewer takes
    them all, the rest share what is left), then within a question type over its sub types in
    proportion (:func:`~spacedg.qa.debias.spread_targets`)."""
    per_scene = Counter((r.scene_id, r.question_type, r.sub_question_type) for r in records)
    targets: Counter[tuple[str, str]] = Counter()
    for (_, question_type, sub_type), n in per_scene.items():
        targets[(question_type, sub_type)] += min(n, per_sub_type)
    out = dict(sorted(targets.items()))
    if max_questions is None:
        return out
    by_type: Counter[str] = Counter()
    for (question_type, _), n in out.items():
        by_type[question_type] += n
    shares = round_robin_shares(by_type, max_questions)
    spread: dict[tuple[str, str], int] = {}
    for question_type, share in shares.items():
        spread.update(spread_targets({k: n for k, n in out.items() if k[0] == question_type}, share))
    return spread


def debias_dataset(dataset: SpaceDGDataset, per_sub_type: int, max_questions: int | None = None, seed: int = 0) -> DebiasResult:
    """Balance the cells' roles of ``dataset.records`` across its scenes (:func:`~spacedg.qa.cell_balance.balance_cells`:
    the candidates took partial rounds), then prune them; in place (their order kept); returns what was done."""
    result = debias_pooled(dataset.records, lambda kept: bench_targets(kept, per_sub_type, max_questions), seed=seed)
    dataset.records = result.kept
    return result


def write_debias_report(result: DebiasResult, out_dir: str | Path) -> None:
    """``debias.json`` and ``debias.md`` in ``out_dir`` (atomic writes)."""
    out = Path(out_dir)
    atomic_write_bytes(out / "debias.json", (json.dumps(result.to_dict(), indent=2) + "\n").encode("utf-8"))
    atomic_write_bytes(out / "debias.md", (format_debias(result) + "\n").encode("utf-8"))

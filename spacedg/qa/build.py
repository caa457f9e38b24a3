"""Per-scene question index: every family's records for a scene, built from a seed, stored as JSONL.

Building one scene (:func:`build_scene_index`):

1. load the scene folder; attach per-view instance visibility and the view covisibility
   matrix, both cached in ``<scene>/cache/`` (``*.visibility.npz``, ``*.covisibility.npz``);
2. for every selected family (sorted by name), run ``family.generate(scene, rng)`` with
   ``rng = default_rng(derive_seed(seed, scene_id, family))``: the records are seeded per
   (scene, family), so adding a family never changes another family's records;
3. pool up to ``pool_factor × per_sub_type`` distinct subjects per ``sub_question_type``
   (each with at most :data:`ALTERNATES` records; no more than ``max_scan`` candidates per
   family) and take up to ``per_sub_type`` of them per sub type with the
   **debiased selection** (:func:`select_records`): a subject (an object, a pair, a view and
   label: the ``selection`` entry of the record's geometry block) is asked at most once per
   sub type; within each *cell* (what a text-only model can tell about the question: its
   labels, its option set, the axes it names) records are taken in whole rounds, one per live
   *role* (answer), so in every scene no function of what the text shows beats chance (the
   blind stress test :mod:`spacedg.data.qa_audit` measures what is left); each role of a round
   is filled with the candidate whose ``features`` (the labels a size comparison names, by
   position) that role has had least, so no label wins more often than it loses; the
   distractors of sector-label questions are dealt again (:func:`deal_distractors`) so every
   label is offered equally often, then the correct letters (:func:`deal_letters`); records without a
   ``selection`` entry (third-party families) are taken round-robin over their correct
   answers as before. An optional judge (:class:`~spacedg.data.judge.DescriptionJudge`) drops
   records whose descriptions it finds ambiguous (asked only about records being taken);
4. write ``<out>/<scene id>.qa.jsonl`` (one :class:`QARecord` per line, families in name
   order) and ``<out>/<scene id>.qa.meta.json`` (key, config, counts, timings) atomically.
   ``out`` defaults to the scene folder itself.

**Full index and selection indexes** (:func:`index_paths`). The *full* index
``<scene id>.qa.jsonl`` holds every registered family (``QABuildConfig.families`` empty): it is
what :class:`~spacedg.data.dataset.SpaceDGDataset` reads by default, what exports and the review
page find. A build restricted to some families (``families=("a", "b")``, ``spacedg qa build
--families a,b``) writes a *selection index* beside it, ``<scene id>.qa.a+b.jsonl`` with
``<scene id>.qa.a+b.meta.json`` (names sorted and joined by ``+``; a selection longer than
:data:`MAX_SELECTION_CHARS` characters is named ``families-<12 hex of its SHA-1>``), and never
touches the full index. Records are seeded per (scene, family), so a selection index holds
exactly the records that family selection has in the full index built with the same settings:
writing it apart loses nothing, while replacing or merging into the full index would leave one
file whose meta key no longer describes its content. A dataset built with
``qa_config=QABuildConfig(families=...)`` reads (and builds) that selection's index.

An index is **reused** when its meta file's key matches: the key hashes the index version,
the build config, the SHA-256 of ``scene.json`` (views, poses, instances) and the selected
families with the distributions and versions that provide them and the SHA-256 of each
family's module source (and the judge's name). Any
change rebuilds it; ``force=True`` always does.
"""

from __future__ import annotations

import dataclasses
import hashlib
import importlib.util
import json
import math
import time
from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from spacedg.data.judge import DescriptionJudge
from spacedg.errors import FileFormatError, ParameterError, SpaceDGError
from spacedg.files import atomic_write_bytes
from spacedg.plugins import get_question_family, list_question_families
from spacedg.plugins.answers import MCQ_LETTERS
from spacedg.plugins.guard import plugin_call
from spacedg.plugins.qa_record import QARecord
from spacedg.plugins.specs import NAME_PATTERN, AnswerType
from spacedg.scene.covisibility import with_covisibility
from spacedg.scene.frame_check import require_frame
from spacedg.scene.io import load_scene
from spacedg.scene.labelling import ensure_instance_ids
from spacedg.scene.lexicon import default_lexicon
from spacedg.scene.model import Scene
from spacedg.scene.store import run_isolated
from spacedg.scene.visibility import (
    compute_visibility,
    load_or_compute_visibility,
    with_visibility,
)
from spacedg.seeding import derive_seed

__all__ = [
    "QA_INDEX_VERSION", "ALTERNATES", "QABuildConfig", "SceneQA", "prepare_scene", "generate_records", "select_records", "deal_distractors", "deal_letters", "with_letter",
    "MAX_SELECTION_CHARS", "selection_name", "index_paths", "build_scene_index", "read_index", "truth_key", "index_is_current", "ensure_indexes",
]

#: Bump when the index layout or the build procedure changes (part of the key).
#: 3: debiased selection (subjects once per sub type, whole rounds per cell), lexicon in the key.
#: 4: pools count distinct subjects (:data:`ALTERNATES` records each); rounds balance the
#: selection entries' ``features`` across roles; distractors of sector-label MCQs dealt evenly.
QA_INDEX_VERSION = 4

#: A subject is pooled with at most this many records (other views of the same question: a
#: compass or direction question's answer changes with the view, so a subject can fill one of
#: several roles, and the judge may drop one); the pool's size counts distinct subjects, so a
#: family whose subjects recur in many views (size comparisons) pools every pair it finds.
ALTERNATES = 8


@dataclass(frozen=True)
class QABuildConfig:
    """How a scene's question index is built.

    Attributes:
        seed: master seed; each (scene, family) draws from ``derive_seed(seed, scene, family)``.
        families: family names to run (empty = every registered family, the *full* index);
            stored sorted and without repeats. A non-empty selection has an index file of its
            own (:func:`index_paths`).
        per_sub_type: at most this many records per ``sub_question_type`` and family.
        max_scan: at most this many candidates examined per family.
        pool_factor: candidates pooled per sub type, as a multiple of ``per_sub_type``, for
            answer balancing (1 = no balancing: the first ``per_sub_type`` in seeded order).
        visibility_size: reduced render size (width, height) px for instance visibility.
        covisibility_size: reduced render size (width, height) px for covisibility.
    """

    seed: int = 0
    families: tuple[str, ...] = ()
    per_sub_type: int = 25
    max_scan: int = 20_000
    pool_factor: int = 40
    visibility_size: tuple[int, int] = (160, 120)
    covisibility_size: tuple[int, int] = (80, 60)

    def __post_init__(self) -> None:
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise ParameterError(f"QABuildConfig: seed must be an integer >= 0, got {self.seed!r}")
        for name in ("per_sub_type", "max_scan", "pool_factor"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ParameterError(f"QABuildConfig: {name} must be a positive integer, got {value!r}")
        if isinstance(self.families, str):
            raise ParameterError(f"QABuildConfig: families must be a sequence of family names, not one string ({self.families!r})")
        object.__setattr__(self, "families", tuple(sorted(set(self.families))))
        object.__setattr__(self, "visibility_size", tuple(self.visibility_size))
        object.__setattr__(self, "covisibility_size", tuple(self.covisibility_size))

    def to_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["families"] = list(self.families)
        out["visibility_size"] = list(self.visibility_size)
        out["covisibility_size"] = list(self.covisibility_size)
        return out


@dataclass
class SceneQA:
    """The result of indexing one scene."""

    scene_id: str
    path: Path
    records: list[QARecord]
    reused: bool
    seconds: dict[str, float] = field(default_factory=dict)
    dropped: dict[str, int] = field(default_factory=dict)

    def counts(self) -> dict[str, int]:
        return dict(sorted(Counter(r.question_type for r in self.records).items()))


# ------------------------------------------------------------------ building
def _families(names: Sequence[str]) -> list[Any]:

    if not names:
        return list_question_families()
    return [get_question_family(n) for n in sorted(set(names))]


def prepare_scene(
    scene: Scene,
    cache_dir: str | Path | None,
    config: QABuildConfig = QABuildConfig(),
    *,
    backend: str = "auto",
    progress: bool = True,
    timings: dict[str, float] | None = None,
    device: str | None = None,
) -> Scene:
    """``scene`` with visibility and covisibility attached (cached under ``cache_dir`` if given).

    First the scene's frame is checked (a scene whose cameras see nothing is refused, naming the
    cause) and Gaussians without instance ids get them by box containment (with a warning)."""

    require_frame(scene, backend=backend)
    scene = ensure_instance_ids(scene)
    t0 = time.perf_counter()
    if cache_dir is None:
        table = compute_visibility(scene, image_size=config.visibility_size, backend=backend, progress=progress, device=device)
    else:
        table = load_or_compute_visibility(scene, cache_dir, image_size=config.visibility_size, backend=backend, progress=progress, device=device)
    scene = with_visibility(scene, table)
    t1 = time.perf_counter()
    scene = with_covisibility(scene, cache_dir, image_size=config.covisibility_size, backend=backend, progress=progress, device=device)
    if timings is not None:
        timings["visibility_s"] = t1 - t0
        timings["covisibility_s"] = time.perf_counter() - t1
    return scene


def truth_key(record: QARecord) -> str | None:
    """What answer balancing groups by: the correct option's text (MCQ), the answer (YN, COUNT),
    or ``None`` for metric answers (NA, SIZE_LIST), which are not balanced."""
    if record.answer_type is AnswerType.MCQ:
        letter = str(record.answer)
        return next((o[3:] for o in record.options if o.startswith(letter + ". ")), letter)
    if record.answer_type in (AnswerType.YN, AnswerType.COUNT):
        return str(record.answer)
    return None


def _select_balanced(pool: list[QARecord], cap: int, keep: Any) -> list[QARecord]:
    """Up to ``cap`` records of one sub type, round-robin over truth buckets (first-seen order).

    Each bucket is consumed in generation order; ``keep(record)`` (the judge) is asked only for
    records about to be taken. The result is returned in generation order. (Records without a
    ``selection`` entry: third-party families.)
    """
    buckets: dict[str | None, list[int]] = {}
    for i, record in enumerate(pool):
        buckets.setdefault(truth_key(record), []).append(i)
    queues = [list(reversed(ix)) for ix in buckets.values()]
    taken: list[int] = []
    while len(taken) < cap and any(queues):
        for queue in queues:
            while queue and len(taken) < cap:
                i = queue.pop()
                if keep(pool[i]):
                    taken.append(i)
                    break
    return [pool[i] for i in sorted(taken)]


def _selection(record: QARecord) -> dict[str, Any] | None:
    entry = record.geometry.get("selection")
    return entry if isinstance(entry, dict) and "subject" in entry else None


def _features(record: QARecord) -> list[str]:
    """The ``features`` of the record's selection entry (what its text names: labels by position)."""
    entry = _selection(record)
    features = entry.get("features") if entry is not None else None
    return [str(f) for f in features] if isinstance(features, list) else []


def select_records(
    records: Sequence[QARecord], per_sub_type: int, keep: Any = None, stats: dict[str, Counter[str]] | None = None,
) -> list[QARecord]:
    """The debiased selection among one family's candidates (in generation order): up to
    ``per_sub_type`` records per sub type, returned in generation order.

    For records with a ``selection`` entry (:func:`~spacedg.plugins.questions.records.selection_entry`):

    - a subject is taken at most once per sub type (``(sub type, subject)``);
    - records with a ``cell`` are taken in **whole rounds**: one record of every role in the
      cell's ``roles`` (or, for an entry with ``all_roles`` false, of the roles the candidates
      offer, at least two), each the first in generation order whose subject is still free (and
      that ``keep`` accepts); a round is taken only while every sub type it touches has room, and a
      cell stops at its first incomplete round. Cells are visited round-robin in the order of
      their first record, one round per visit, until no cell can give a round;
    - a role of a round is filled, among the free candidates of that role, with the one whose
      selection ``features`` the role has had least so far in the sub type (greedy: the sum
      over its features of the role's count minus the mean count over the cell's roles;
      ties, and records without features: generation order);
    - records without a ``cell`` (metric answers) are taken in generation order;
    - a sub type whose ``per_sub_type`` is smaller than every round of its cells (e.g. 1) takes
      its first free candidates in generation order instead, so a small index is not empty.

    Records without a ``selection`` entry are taken per sub type round-robin over their correct
    answers (:func:`truth_key`), as before version 3.

    ``stats`` (optional) receives per sub type: ``pooled``, ``taken``, and why the others were
    not: ``repeat`` (subject already asked), ``quota`` (its sub type has no room for another
    round of its cell), ``unbalanced`` (no complete round of its cell left), ``judge``.
    """
    keep = keep or (lambda record: True)
    judged_out: set[str] = set()

    def accept(record: QARecord) -> bool:
        if record.id in judged_out:
            return False
        if keep(record):
            return True
        judged_out.add(record.id)
        return False

    room: Counter[str] = Counter()
    for r in records:
        room[r.sub_question_type] = per_sub_type
    taken: set[int] = set()
    subjects: set[tuple[str, str]] = set()
    plain: dict[str, list[int]] = {}
    metric: list[int] = []
    cells: dict[str, dict[str, list[int]]] = {}
    cell_roles: dict[str, list[str]] = {}
    partial: set[str] = set()
    selections = [_selection(r) for r in records]
    features_of = [_features(r) for r in records]
    subject_of = [None if sel is None else (r.sub_question_type, str(sel["subject"])) for r, sel in zip(records, selections)]
    for i, r in enumerate(records):
        sel = selections[i]
        if sel is None:
            plain.setdefault(r.sub_question_type, []).append(i)
        elif "cell" not in sel:
            metric.append(i)
        else:
            cell = f"{r.question_type}|{sel['cell']}"
            cells.setdefault(cell, {}).setdefault(str(sel["role"]), []).append(i)
            cell_roles.setdefault(cell, [str(x) for x in sel.get("roles", [])])
            if sel.get("all_roles", True) is False:
                partial.add(cell)
    for cell in partial:  # rounds over the roles this scene offers in the cell (at least two)
        offered = [role for role in cell_roles[cell] if cells[cell].get(role)]
        cell_roles[cell] = offered if len(offered) >= 2 else []

    def subject(i: int) -> tuple[str, str]:
        return subject_of[i]  # type: ignore[return-value]

    # metric answers: generation order, subjects once
    for i in metric:
        r = records[i]
        if room[r.sub_question_type] > 0 and subject(i) not in subjects and accept(r):
            taken.add(i)
            subjects.add(subject(i))
            room[r.sub_question_type] -= 1
    # balanced cells: whole rounds, round-robin over cells
    cursors = {cell: {role: 0 for role in roles} for cell, roles in cell_roles.items()}
    # feature balance: (sub type, feature) → role → records taken (features: what the text names)
    balance: dict[tuple[str, str], Counter[str]] = {}

    def cost(i: int, role: str, roles: Sequence[str]) -> float:
        """How over-represented record i's features already are in ``role`` (greedy chi-square)."""
        sub = records[i].sub_question_type
        total = 0.0
        for f in features_of[i]:
            row = balance.get((sub, f))
            if row:
                total += row[role] - sum(row[r] for r in roles) / len(roles)
        return total

    def pick(cell: str, role: str, used: set[tuple[str, str]]) -> int | None:
        """The candidate of ``role`` in ``cell`` for the next round: free subject, accepted by the
        judge; among them the least over-represented features (ties: generation order)."""
        queue = cells[cell].get(role, [])
        k = cursors[cell][role]
        while k < len(queue) and (subject(queue[k]) in subjects or records[queue[k]].id in judged_out):
            k += 1  # never usable again
        cursors[cell][role] = k
        while True:
            best, best_cost = None, math.inf
            for i in queue[k:]:
                if subject(i) in subjects or subject(i) in used or records[i].id in judged_out:
                    continue
                c = cost(i, role, cell_roles[cell]) if featured[cell] else 0.0
                if c < best_cost:
                    best, best_cost = i, c
                    if not featured[cell]:
                        break
            if best is None:
                return None
            if accept(records[best]):
                return best

    featured = {cell: any(features_of[i] for q in by_role.values() for i in q) for cell, by_role in cells.items()}
    # a cell needs two roles at least: a one-role cell would be answered by its text alone
    open_cells = [c for c in cells if len(cell_roles[c]) >= 2 and all(cells[c].get(role) for role in cell_roles[c])]
    while open_cells:
        still = []
        for cell in open_cells:
            round_: list[int] = []
            used: set[tuple[str, str]] = set()
            need: Counter[str] = Counter()
            complete = True
            for role in cell_roles[cell]:
                i = pick(cell, role, used)
                if i is None:
                    complete = False
                    break
                round_.append(i)
                used.add(subject(i))
                need[records[i].sub_question_type] += 1
            if not complete or any(room[sub] < n for sub, n in need.items()):
                continue  # the cell is exhausted, or a sub type it needs is full
            for i in round_:
                taken.add(i)
                subjects.add(subject(i))
                room[records[i].sub_question_type] -= 1
                role = str(selections[i]["role"])  # type: ignore[index]
                for f in features_of[i]:
                    balance.setdefault((records[i].sub_question_type, f), Counter())[role] += 1
            still.append(cell)
        open_cells = still
    # a sub type whose quota is smaller than every round of its cells (a tiny per_sub_type, e.g.
    # 1) would stay empty: it takes its first free candidates in generation order instead (too
    # few to balance anyway)
    got = Counter(records[i].sub_question_type for i in taken)
    smallest: dict[str, int] = {}
    for cell, by_role in cells.items():
        size = len(cell_roles[cell])
        for queue in by_role.values():
            for i in queue:
                sub = records[i].sub_question_type
                smallest[sub] = min(smallest.get(sub, size), size) if size >= 2 else smallest.get(sub, 10**9)
    for i in sorted(i for by_role in cells.values() for queue in by_role.values() for i in queue):
        r = records[i]
        sub = r.sub_question_type
        if got[sub] == 0 and 0 < room[sub] < smallest.get(sub, 0) and subject(i) not in subjects and accept(r):
            taken.add(i)
            subjects.add(subject(i))
            room[sub] -= 1
    # records of families without selection entries
    for sub, ix in plain.items():
        first: dict[str, int] = {}
        for i in ix:
            first.setdefault(records[i].id, i)
        for r in _select_balanced([records[i] for i in ix], per_sub_type, accept):
            taken.add(first[r.id])

    def _round_size(i: int) -> int:
        sel, r = selections[i], records[i]
        if sel is None or "cell" not in sel:
            return 1
        roles = cell_roles.get(f"{r.question_type}|{sel['cell']}") or sel.get("roles", [])
        return max(1, len(roles))

    if stats is not None:
        for i, r in enumerate(records):
            row = stats.setdefault(r.sub_question_type, Counter())
            row["pooled"] += 1
            if i in taken:
                row["taken"] += 1
            elif r.id in judged_out:
                row["judge"] += 1
            elif selections[i] is not None and subject(i) in subjects:
                row["repeat"] += 1
            elif room[r.sub_question_type] < _round_size(i):
                row["quota"] += 1  # no room for another round of its cell
            else:
                row["unbalanced"] += 1
    return [records[i] for i in sorted(taken)]


def with_letter(record: QARecord, slot: int) -> QARecord:
    """``record`` (MCQ) with its correct option moved to letter ``slot`` (0–3), the other options
    keeping their order: the same question and answer text, another letter."""

    texts = [line[3:] for line in record.options]
    k = MCQ_LETTERS.index(str(record.answer))
    others = texts[:k] + texts[k + 1:]
    texts = others[:slot] + [texts[k]] + others[slot:]
    return dataclasses.replace(
        record, options=tuple(f"{MCQ_LETTERS[i]}. {t}" for i, t in enumerate(texts)), answer=MCQ_LETTERS[slot],
    )


def deal_distractors(records: Sequence[QARecord], rng: np.random.Generator) -> list[QARecord]:
    """The MCQ ``records`` whose selection entry lists ``distractors`` (the texts that may be one)
    with their three distractors dealt again, per sub type: the truths stay, and the
    distractors of each record (visited in an order drawn from ``rng``) are the allowed texts
    offered least often so far in the sub type (ties broken by ``rng``), in an ``rng`` order. So
    every text is offered about equally often, and, the truths being balanced by the rounds,
    is right about as often as any other when offered (a text offered more often than the others
    would be right less often, which a blind model learns). The correct option keeps its letter
    (:func:`deal_letters` deals the letters afterwards); other records are returned unchanged."""

    out = list(records)
    by_sub: dict[str, list[int]] = {}
    for k, r in enumerate(out):
        sel = _selection(r)
        if r.answer_type is AnswerType.MCQ and sel is not None and isinstance(sel.get("distractors"), list):
            by_sub.setdefault(r.sub_question_type, []).append(k)
    for sub in sorted(by_sub):
        ks = by_sub[sub]
        offered: Counter[str] = Counter(truth_key(out[k]) for k in ks)
        for j in rng.permutation(len(ks)):
            r = out[ks[int(j)]]
            truth = str(truth_key(r))
            allowed = sorted({str(t) for t in _selection(r)["distractors"]} - {truth})  # type: ignore[index]
            if len(allowed) < 3:
                continue
            ties = rng.random(len(allowed))
            picked = [allowed[i] for i in sorted(range(len(allowed)), key=lambda i: (offered[allowed[i]], ties[i]))[:3]]
            picked = [picked[i] for i in rng.permutation(3)]
            offered.update(picked)
            slot = MCQ_LETTERS.index(str(r.answer))
            texts = picked[:slot] + [truth] + picked[slot:]
            out[ks[int(j)]] = dataclasses.replace(r, options=tuple(f"{MCQ_LETTERS[i]}. {t}" for i, t in enumerate(texts)))
    return out


def deal_letters(records: Sequence[QARecord], rng: np.random.Generator) -> list[QARecord]:
    """The MCQ ``records`` with their correct letters dealt again, per sub type in the given
    order, from shuffled A–D blocks of ``rng``: the letters of each sub type of a scene's index
    are uniform to within one block (the selection keeps a subset of a family's records, whose
    letters were balanced over the whole generation only). Only records with a ``selection``
    entry are re-lettered: their geometry never refers to option positions (families without
    one keep their letters)."""
    decks: dict[str, list[int]] = {}
    out = []
    for r in records:
        if r.answer_type is not AnswerType.MCQ or _selection(r) is None:
            out.append(r)  # a family without selection entries may tie its geometry to the option order
            continue
        deck = decks.setdefault(r.sub_question_type, [])
        if not deck:
            deck.extend(int(v) for v in rng.permutation(4))
        out.append(with_letter(r, deck.pop()))
    return out


def generate_records(
    scene: Scene,
    config: QABuildConfig = QABuildConfig(),
    *,
    judge: Any = None,
    dropped: dict[str, int] | None = None,
    selection_stats: dict[str, dict[str, int]] | None = None,
) -> list[QARecord]:
    """Records of every selected family for a prepared scene (see the module docstring).

    Per family, candidates are pooled (up to ``pool_factor × per_sub_type`` distinct subjects
    per sub type, :data:`ALTERNATES` records each, ``max_scan`` candidates in all); then
    :func:`select_records` takes up to ``per_sub_type`` per sub type: each subject once, whole
    rounds of every cell's roles (no answer is predictable from what the text shows), metric
    answers in generation order; the kept sector-label MCQs get their distractors dealt again
    (:func:`deal_distractors`, seeded by ``derive_seed(seed, scene, family, "distractors")``)
    and the kept MCQ records their correct letters (:func:`deal_letters`, seeded by
    ``derive_seed(seed, scene, family, "letters")``), so letters are uniform per sub type.

    ``judge``: a callable ``judge(image, label, description) -> "KEEP"/"DROP"`` or a
    :class:`~spacedg.data.judge.DescriptionJudge`, asked only about records being taken;
    ``dropped`` receives per-family counts of records the judge removed; ``selection_stats``
    receives per ``question_type/sub_question_type`` the counts of :func:`select_records`.
    """

    if judge is not None and not isinstance(judge, DescriptionJudge):
        judge = DescriptionJudge(scene, judge)
    out: list[QARecord] = []
    want = config.per_sub_type * config.pool_factor
    for family in _families(config.families):
        rng = np.random.default_rng(derive_seed(config.seed, scene.id, family.name))
        pooled: list[QARecord] = []  # in scan order
        distinct: dict[str, Counter[str]] = {}  # sub type → pooled records per subject
        with plugin_call("question family", family, "generate"):
            for scanned, record in enumerate(family.generate(scene, rng)):
                if scanned >= config.max_scan:
                    break
                seen = distinct.setdefault(record.sub_question_type, Counter())
                sel = _selection(record)
                subject = str(sel["subject"]) if sel is not None else f"record:{record.id}"
                if seen[subject] >= ALTERNATES:
                    continue  # a subject already pooled (another view of the same question)
                if subject in seen or len(seen) < want:
                    seen[subject] += 1
                    pooled.append(record)
                elif all(len(distinct.get(s, ())) >= want for s in family.sub_question_types):
                    break

        def keep(record: QARecord, family_name: str = family.name) -> bool:
            if judge is None or judge.keep(record):
                return True
            if dropped is not None:
                dropped[family_name] = dropped.get(family_name, 0) + 1
            return False

        stats: dict[str, Counter[str]] = {}
        chosen = select_records(pooled, config.per_sub_type, keep, stats)
        chosen = deal_distractors(chosen, np.random.default_rng(derive_seed(config.seed, scene.id, family.name, "distractors")))
        chosen = deal_letters(chosen, np.random.default_rng(derive_seed(config.seed, scene.id, family.name, "letters")))
        by_sub: dict[str, list[QARecord]] = {}
        for r in chosen:
            by_sub.setdefault(r.sub_question_type, []).append(r)
        for sub in family.sub_question_types:
            out.extend(by_sub.get(sub, []))
        if selection_stats is not None:
            for sub, row in stats.items():
                selection_stats[f"{family.name}/{sub}"] = dict(sorted(row.items()))
    return out


#: A family selection whose ``+``-joined names are longer than this is named by its hash.
MAX_SELECTION_CHARS = 100


def selection_name(families: Sequence[str]) -> str:
    """The file-name part of a family selection: ``""`` for the full index (no selection), else
    the sorted distinct names joined by ``+`` (``"object_counting+camera_rotation"`` order-free),
    or ``families-<first 12 hex of the SHA-1 of that text>`` when it exceeds :data:`MAX_SELECTION_CHARS`."""
    names = sorted(set(families))
    for name in names:
        if not isinstance(name, str) or not NAME_PATTERN.match(name):
            raise ParameterError(f"family selection: {name!r} is not a family name (^[a-z][a-z0-9_]*$); see `spacedg plugins`")
    text = "+".join(names)
    if len(text) > MAX_SELECTION_CHARS:
        return "families-" + hashlib.sha1(text.encode("utf-8")).hexdigest()[:12]
    return text


def index_paths(scene_id: str, out_dir: str | Path, families: Sequence[str] = ()) -> tuple[Path, Path]:
    """``(<out>/<id>.qa.jsonl, <out>/<id>.qa.meta.json)``: the full index; with ``families``, the
    selection index ``(<out>/<id>.qa.<selection>.jsonl, <out>/<id>.qa.<selection>.meta.json)``
    (:func:`selection_name`; see the module docstring)."""
    out = Path(out_dir)
    selection = selection_name(families)
    stem = f"{scene_id}.qa" if not selection else f"{scene_id}.qa.{selection}"
    return out / f"{stem}.jsonl", out / f"{stem}.meta.json"


def _index_key(scene_json: Path, config: QABuildConfig, families: Iterable[Any], judge: Any) -> str:
    digest = hashlib.sha256()
    digest.update(scene_json.read_bytes())
    fams = []
    for fam in families:
        origin = fam.origin
        fams.append([fam.name, getattr(origin, "distribution", None), getattr(origin, "version", None), _module_digest(fam)])

    judge_name = None if judge is None else getattr(judge, "__name__", type(judge).__name__)
    head = {
        "version": QA_INDEX_VERSION, "config": config.to_dict(), "families": fams, "judge": judge_name,
        "lexicon": default_lexicon().digest(),
    }
    digest.update(json.dumps(head, sort_keys=True).encode())
    return digest.hexdigest()


def _module_digest(family: Any) -> str | None:
    """SHA-256 of the source of the modules that make the family's records (so editing a family
    rebuilds indexes even without a version bump): the module of its raw ``generate`` and, when
    that is a ``functools.partial`` (what a family factory such as
    :func:`~spacedg.plugins.questions.pairs.pair_family` stores), of the functions bound into it
    (a pair family's stream). One module: the SHA-256 of its file; several: the SHA-256 of their
    files' digests in that order. ``None`` when none has a file."""
    raw = getattr(family.generate, "__wrapped__", family.generate)
    func = getattr(raw, "func", None)  # functools.partial
    parts = [raw] if func is None else [func, *(p for p in (*raw.args, *raw.keywords.values()) if callable(p))]
    modules = dict.fromkeys(getattr(part, "__module__", None) for part in parts)
    files = []
    for module in filter(None, modules):
        spec = importlib.util.find_spec(module)
        if spec is not None and spec.origin and Path(spec.origin).is_file():
            files.append(hashlib.sha256(Path(spec.origin).read_bytes()))
    if len(files) < 2:
        return files[0].hexdigest() if files else None
    return hashlib.sha256(b"".join(f.digest() for f in files)).hexdigest()


def _read_meta(path: Path) -> dict[str, Any] | None:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def build_scene_index(
    scene_dir: str | Path,
    config: QABuildConfig = QABuildConfig(),
    *,
    out_dir: str | Path | None = None,
    judge: Any = None,
    force: bool = False,
    backend: str = "auto",
    progress: bool = True,
    device: str | None = None,
) -> SceneQA:
    """Build (or reuse) the question index of one native scene folder (see the module docstring):
    the full index, or with ``config.families`` the selection index beside it (:func:`index_paths`)."""

    scene_dir = Path(scene_dir)
    scene = load_scene(scene_dir)
    scene_json = scene_dir / "scene.json" if scene_dir.is_dir() else scene_dir
    key = _index_key(scene_json, config, _families(config.families), judge)
    jsonl, meta_path = index_paths(scene.id, out_dir if out_dir is not None else scene_json.parent, config.families)
    if not force and _is_current(jsonl, meta_path, key):
        meta = _read_meta(meta_path) or {}
        return SceneQA(scene.id, jsonl, read_index(jsonl), reused=True, seconds=dict(meta.get("seconds", {})))
    timings: dict[str, float] = {}
    prepared = prepare_scene(scene, scene_json.parent / "cache", config, backend=backend, progress=progress, timings=timings, device=device)
    dropped: dict[str, int] = {}
    selection: dict[str, dict[str, int]] = {}
    t0 = time.perf_counter()
    records = generate_records(prepared, config, judge=judge, dropped=dropped, selection_stats=selection)
    timings["generate_s"] = time.perf_counter() - t0
    body = "".join(r.to_json() + "\n" for r in records).encode("utf-8")
    jsonl.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(jsonl, body)
    meta = {
        "format": "spacedg-qa-index", "version": QA_INDEX_VERSION, "key": key, "scene_id": scene.id,
        "config": config.to_dict(), "records": len(records),
        "counts": dict(sorted(Counter(r.question_type for r in records).items())),
        "dropped_by_judge": dropped, "selection": selection, "seconds": {k: round(v, 4) for k, v in timings.items()},
    }
    atomic_write_bytes(meta_path, (json.dumps(meta, indent=2) + "\n").encode("utf-8"))
    return SceneQA(scene.id, jsonl, records, reused=False, seconds=timings, dropped=dropped)


def _is_current(jsonl: Path, meta_path: Path, key: str) -> bool:
    meta = _read_meta(meta_path)
    return meta is not None and meta.get("key") == key and jsonl.is_file()


def index_is_current(scene_dir: str | Path, config: QABuildConfig = QABuildConfig(), out_dir: str | Path | None = None) -> bool:
    """Whether ``build_scene_index(scene_dir, config, out_dir=out_dir)`` would reuse its index
    (reads ``scene.json`` and the meta file only: nothing is rendered)."""

    scene_dir = Path(scene_dir)
    scene_json = scene_dir / "scene.json" if scene_dir.is_dir() else scene_dir
    scene_id = load_scene(scene_dir).id
    jsonl, meta_path = index_paths(scene_id, out_dir if out_dir is not None else scene_json.parent, config.families)
    return _is_current(jsonl, meta_path, _index_key(scene_json, config, _families(config.families), None))


def read_index(path: str | Path) -> list[QARecord]:
    """Records of a ``*.qa.jsonl`` file; :class:`FileFormatError` naming the file and line on bad input."""
    path = Path(path)
    records = []
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except OSError as err:
        raise FileFormatError(f"{path}: cannot read the question index ({err.strerror})") from err
    for number, line in enumerate(lines, 1):
        if not line.strip():
            continue
        try:
            records.append(QARecord.from_json(line))
        except Exception as err:  # noqa: BLE001 - report which line is bad
            raise FileFormatError(f"{path}:{number}: not a question record ({err}); rebuild with `spacedg qa build`") from err
    return records


# --------------------------------------------------------- many scenes, isolated
def _build_indexes(payload: dict[str, Any]) -> dict[str, str]:
    """Child side of :func:`ensure_indexes`: build the indexes of ``payload["dirs"]``; returns
    ``folder → error message`` for the scenes that failed."""
    from tqdm import tqdm


    config = payload["config"]
    cfg = QABuildConfig(**{**config, "families": tuple(config["families"]), "visibility_size": tuple(config["visibility_size"]),
                           "covisibility_size": tuple(config["covisibility_size"])})
    failed: dict[str, str] = {}
    for folder in tqdm(payload["dirs"], desc="question indexes (first use)", unit="scene"):
        try:
            build_scene_index(folder, cfg, progress=False)
        except (SpaceDGError, OSError, ValueError) as err:
            failed[folder] = str(err)
    return failed


def ensure_indexes(dirs: Sequence[Path], config: QABuildConfig) -> dict[str, str]:
    """Build the question index of each scene folder whose index is missing or stale, **in a
    separate Python process** (:func:`~spacedg.scene.store.run_isolated`: the caller never starts
    numba or CUDA threads before a DataLoader forks its workers); returns ``folder → error`` for
    scenes that could not be read or indexed."""

    failed: dict[str, str] = {}
    stale = []
    for d in dirs:
        try:
            if not index_is_current(d, config):
                stale.append(str(d))
        except (SpaceDGError, OSError, ValueError) as err:
            failed[str(d)] = str(err)
    if stale:
        failed.update(run_isolated("spacedg.data.qa_index:_build_indexes", {"dirs": stale, "config": config.to_dict()}))
    return failed

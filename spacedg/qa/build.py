"""Per-scene question index: every family's records for a scene, built from a seed, stored as JSONL.

Building one scene (:func:`build_scene_index`):

1. load the scene folder; attach per-view instance visibility and the view covisibility
   matrix, both cached in ``<scene>/cache/`` (``*.visibility.npz``, ``*.covisibility.npz``);
2. for every selected family (sorted by name), run ``family.generate(scene, rng)`` with
   ``rng = default_rng(derive_seed(seed, scene_id, family))``: the records are seeded per
   (scene, family), so adding a family never changes another family's records;
3. pool up to ``pool_factor × per_sub_type`` distinct subjects per ``sub_question_type``
   (each with at most :data:`ALTERNATES` records; no more than ``max_scan`` candidates per
   family; without a judge, a family that declares ``metric_only`` stops as soon as each of its
   sub types has its quota of selection subjects, all the selection can take, and one that declares
   ``plain_rounds`` once the selection of what it has read is provably final,
   :func:`~spacedg.qa.selection.prefix_settles`) and take up to ``per_sub_type`` of them per sub type with the
   **debiased selection** (:func:`~spacedg.qa.selection.select_records`): a subject (an object, a pair, a view and
   label: the ``selection`` entry of the record's geometry block) is asked at most once per
   sub type; within each *cell* (what a text-only model can tell about the question: its
   labels, its option set, the axes it names) records are taken in whole rounds, one per live
   *role* (answer), so in every scene no function of what the text shows beats chance (the
   blind stress test :mod:`spacedg.qa.audit` measures what is left); each role of a round
   is filled with the candidate whose ``features`` (the labels a size comparison names, by
   position) that role has had least, so no label wins more often than it loses; the
   distractors of sector-label questions are dealt again (:func:`~spacedg.qa.deal.deal_distractors`) so every
   label is offered equally often, then the correct letters (:func:`~spacedg.qa.deal.deal_letters`); records without a
   ``selection`` entry (third-party families) are taken round-robin over their correct
   answers as before. An optional judge (:class:`~spacedg.qa.judge.DescriptionJudge`) drops
   records whose descriptions it finds ambiguous (asked only about records being taken);
4. write ``<out>/<scene id>.qa.jsonl`` (one :class:`~spacedg.plugins.qa_record.QARecord` per line, families in name
   order) and ``<out>/<scene id>.qa.meta.json`` (key, config, counts, timings) atomically.
   ``out`` defaults to the scene folder itself.

Where the files go and when an index is reused: :mod:`spacedg.qa.index`.
"""
from __future__ import annotations

import contextlib
import functools
import math
import time
from collections import Counter
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from spacedg.errors import PluginError, SpaceDGError
from spacedg.plugins.guard import plugin_call
from spacedg.plugins.candidates import PASSED_OVER, Candidate, gated, light_candidates
from spacedg.plugins.qa_record import QARecord, deferred_geometry
from spacedg.qa.deal import deal_distractors, deal_letters
from spacedg.qa.gc_pause import collector_paused
from spacedg.qa.index import (
    QA_INDEX_VERSION,
    QABuildConfig,
    SceneQA,
    index_is_current,
    index_key,
    config_index_paths,
    is_current,
    read_index,
    read_meta,
    scene_json_path,
    selected_families,
    write_index,
)
from spacedg.qa.judge import DescriptionJudge
from spacedg.plugins.questions.view_sampling import VisibilityIndex, shared_visibility_tables
from spacedg.qa.modes import quota, subject_key
from spacedg.qa.pooled import Pooled
from spacedg.qa.selection import prefix_settles, select_records, selection_of
from spacedg.qa.twins import TwinCheck, named_ids
from spacedg.scene.covisibility import with_covisibility
from spacedg.scene.frame_check import require_frame
from spacedg.scene.io import load_scene
from spacedg.scene.labelling import ensure_instance_ids
from spacedg.scene.model import Scene
from spacedg.scene.store import run_isolated
from spacedg.scene.visibility import (
    compute_visibility,
    load_or_compute_visibility,
    with_visibility,
)
from spacedg.seeding import derive_seed

__all__ = ["ALTERNATES", "prepare_scene", "generate_records", "build_scene_index", "ensure_indexes"]

#: A subject is pooled with at most this many records (other views of the same question: a
#: compass or direction question's answer changes with the view, so a subject can fill one of
#: several roles, and the judge may drop one); the pool's size counts distinct subjects, so a
#: family whose subjects recur in many views (size comparisons) pools every pair it finds.
ALTERNATES = 8
#: A ``plain_rounds`` family's pool is first offered to :func:`~spacedg.qa.selection.prefix_settles`
#: at this many records, then each time it has grown by :data:`ROUNDS_CHECK_GROWTH` (each check
#: runs the selection on the pool so far: the checks cost about ``growth / (growth − 1)`` selections
#: of the final pool, 5 at 1.25, and the scan reads up to ``growth − 1`` more of it than it needs).
ROUNDS_FIRST_CHECK = 64
ROUNDS_CHECK_GROWTH = 1.25


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


class _ScanDone(BaseException):
    """Raised by the pool's gate or its note of a pooled record to end a family's scan (``max_scan``
    reached, every sub type has its subjects, or a ``metric_only`` or ``plain_rounds`` family's selection is final). A
    :class:`BaseException`, so a family's own ``except Exception`` never swallows it."""


class _PoolScan:
    """The pool's rules for one family (see :func:`_pool`), asked about candidates already made
    (:meth:`take`) and, through :func:`~spacedg.plugins.candidates.gated`, about valid
    candidates before a family draws for them (:meth:`gate`; a refused one comes back as
    :data:`~spacedg.plugins.candidates.PASSED_OVER` and is counted then, :meth:`passed_over`).
    A candidate is refused when its subject already has :data:`ALTERNATES` records, when it is a
    new subject and its sub type has ``want`` subjects (the scan ends at a new subject, not a
    twin, once every sub type has them), and when an object it names has a twin in one of its
    images (counted in ``twins``, except for a subject that already has its alternates: that
    rule comes first, as it is the one most candidates meet). For a family that declares
    ``metric_only`` or ``plain_rounds`` (no judge), :meth:`pooled` ends the scan once the selection could take nothing else."""

    def __init__(self, family: Any, config: QABuildConfig, index: TwinCheck, twins: Counter[str], stop_early: bool = False) -> None:
        self.family, self.index, self.twins = family, index, twins
        self.max_scan = config.max_scan
        self.quota = quota(config.per_sub_type, config.mode)
        self.want = self.quota * config.pool_factor
        self.mode = config.mode
        self.scanned = 0
        self.distinct: dict[str, dict[str, int]] = {}  # sub type → pooled records per subject
        self.admitted: tuple[str, Sequence[str], str, Sequence[int]] | None = None  # what the gate last admitted
        # sub type → the selection's subjects (subject_key) pooled so far, for a family that declares metric_only
        self.metric: dict[str, set[str]] | None = (
            {sub: set() for sub in family.sub_question_types} if getattr(family, "metric_only", False) else None
        )
        # cell → its sub type, for a family that declares plain_rounds
        self.cell_subs: dict[str, str] | None = {} if getattr(family, "plain_rounds", False) else None
        # per cell, the roles of its round (its first record's, as the selection reads them) not seen yet and
        # the round's size; per sub type, the records the first visit to its complete cells could take (no
        # prefix settles before that reaches quota − 1: a cell takes at most one round per visit)
        self.roles_missing: dict[str, tuple[set[str], int]] = {}
        self.capacity: Counter[str] = Counter()
        self.stop_early = stop_early
        # a plain_rounds family's pool is offered to prefix_settles at these sizes (none with partial rounds: the proof does not cover them)
        self.next_check = ROUNDS_FIRST_CHECK if stop_early and self.cell_subs is not None and not config.partial_rounds else None

    def _wanted(self, sub: str, views: Sequence[str], subject: str, named: Sequence[int]) -> bool:
        """Whether the pool takes the candidate (class docstring); raises :class:`_ScanDone` when a
        new subject arrives and every sub type has ``want`` subjects."""
        seen = self.distinct.get(sub)
        if seen is None:
            seen = self.distinct[sub] = {}
        pooled = seen.get(subject, 0)
        if pooled >= ALTERNATES:
            return False  # a subject already pooled (another view of the same question)
        twin = bool(named) and self.index.has_twin_ids(views, named)
        if twin:
            self.twins[self.family.name] += 1
            return False
        if not pooled and len(seen) >= self.want:
            if all(len(self.distinct.get(s, ())) >= self.want for s in self.family.sub_question_types):
                raise _ScanDone
            return False
        return True

    def gate(self, sub: str, views: tuple[str, ...], subject: str, named: tuple[int, ...]) -> bool:
        """Whether a valid candidate is wanted, before the family draws for it (counted when the
        family yields it or, refused, :data:`~spacedg.plugins.candidates.PASSED_OVER`)."""
        if self.scanned >= self.max_scan:
            raise _ScanDone
        seen = self.distinct.get(sub)
        if seen is not None and seen.get(subject, 0) >= ALTERNATES:
            self.admitted = None
            return False  # the commonest refusal (the first rule of _wanted), without the call
        wanted = self._wanted(sub, views, subject, named)
        self.admitted = (sub, views, subject, named) if wanted else None
        return wanted

    def _count(self) -> None:
        """One more candidate scanned (the scan ends at ``max_scan``)."""
        if self.scanned >= self.max_scan:
            raise _ScanDone
        self.scanned += 1

    def passed_over(self) -> None:
        """A candidate :meth:`gate` refused: counted as scanned (:meth:`_count`, written out: most candidates end here)."""
        if self.scanned >= self.max_scan:
            raise _ScanDone
        self.scanned += 1
        self.admitted = None

    def take(self, sub: str, views: Sequence[str], subject: str, named: Sequence[int]) -> bool:
        """A candidate the family yielded: counted as scanned; whether the pool keeps it (and then noted).
        One the gate has just admitted with these very fields is not asked again (nothing changed since)."""
        self._count()
        admitted, self.admitted = self.admitted, None
        if admitted != (sub, views, subject, named) and not self._wanted(sub, views, subject, named):
            return False
        seen = self.distinct[sub]
        seen[subject] = seen.get(subject, 0) + 1
        return True

    def pooled(self, record: QARecord, pool: Sequence[QARecord]) -> None:
        """A record just pooled (the last of ``pool``). A family that declares ``metric_only`` or
        ``plain_rounds`` is held to it (a pooled record that breaks the promise is refused, judge or
        not). With ``stop_early`` (no judge) the scan then ends as soon as no later candidate could
        change the selection:

        - ``metric_only``: once every sub type has ``quota`` distinct selection subjects
          (:func:`~spacedg.qa.modes.subject_key`): the selection takes a record without a cell only
          while its sub type has room, in generation order, one per subject
          (:meth:`~spacedg.qa.selection._Selection.take_metric`), and with no room left no round,
          partial round or small quota takes anything either;
        - ``plain_rounds`` (and no partial rounds): once :func:`~spacedg.qa.selection.prefix_settles`
          proves the selection of the pool so far final, asked when the pool reaches
          :data:`ROUNDS_FIRST_CHECK` records and then every :data:`ROUNDS_CHECK_GROWTH` times more.

        (A judge may refuse pooled records, so with one every candidate is read.)"""
        if self.metric is not None:
            self._metric_pooled(record, self.metric)
        elif self.cell_subs is not None:
            self._rounds_pooled(record, pool, self.cell_subs)

    def _broken(self, promise: str, what: str, entry: dict[str, Any] | None) -> PluginError:
        """The refusal of a pooled record that breaks the family's declared ``promise``."""
        subject = entry.get("subject") if entry else None
        return PluginError(
            f"question family {self.family.name!r} declares {promise}, but offered a {what} (subject {subject!r}); "
            f"declare {promise}=False for a family whose records do not all keep that promise"
        )

    def _metric_pooled(self, record: QARecord, metric: dict[str, set[str]]) -> None:
        entry = selection_of(record)
        keys = metric.get(record.sub_question_type)
        if entry is None:
            raise self._broken("metric_only", "record without a selection entry", entry)
        if "cell" in entry:
            raise self._broken("metric_only", "balanced record (a selection cell)", entry)
        if keys is None:
            raise self._broken("metric_only", f"record of the undeclared sub type {record.sub_question_type!r}", entry)
        if not self.stop_early:
            return
        keys.add(subject_key(str(entry["subject"]), record.views, self.mode))
        if all(len(k) >= self.quota for k in metric.values()):
            raise _ScanDone

    def _rounds_pooled(self, record: QARecord, pool: Sequence[QARecord], cell_subs: dict[str, str]) -> None:
        entry = selection_of(record)
        sub = record.sub_question_type
        if entry is None:
            raise self._broken("plain_rounds", "record without a selection entry", entry)
        if "cell" not in entry:
            raise self._broken("plain_rounds", "metric record (no selection cell)", entry)
        if entry.get("all_roles", True) is False:
            raise self._broken("plain_rounds", "record whose cell asks only the roles offered (all_roles false)", entry)
        if entry.get("features"):
            raise self._broken("plain_rounds", "record with selection features", entry)
        if sub not in self.family.sub_question_types:
            raise self._broken("plain_rounds", f"record of the undeclared sub type {sub!r}", entry)
        cell = str(entry["cell"])
        cell_sub = cell_subs.setdefault(cell, sub)
        if cell_sub != sub:
            raise self._broken("plain_rounds", f"record of sub type {sub!r} in a cell of sub type {cell_sub!r}", entry)
        state = self.roles_missing.get(cell)
        if state is None:  # the cell's first record: its roles are the round's, as the selection reads them
            roles = entry.get("roles", ())
            state = self.roles_missing[cell] = ({str(r) for r in roles}, len(roles))
        missing, size = state
        if missing:
            missing.discard(str(entry["role"]))
            if not missing and size >= 2:
                self.capacity[sub] += size  # the cell is complete: its first visit may take a round
        if self.next_check is None or len(pool) < self.next_check:
            return
        if any(self.capacity[s] < self.quota - 1 for s in self.family.sub_question_types):
            return  # the first visits cannot fill every sub type yet: no prefix settles
        if prefix_settles(pool, self.quota, self.mode, self.family.sub_question_types):
            raise _ScanDone
        self.next_check = math.ceil(len(pool) * ROUNDS_CHECK_GROWTH)


def _pool(family: Any, scene: Scene, config: QABuildConfig, index: TwinCheck, twins: Counter[str], stop_early: bool = False) -> list[QARecord]:
    """A family's candidates in scan order: up to ``pool_factor × quota`` distinct subjects
    (the family's own, views included: the mode's stricter subjects are the selection's job) per sub type, :data:`ALTERNATES`
    records each, ``max_scan`` candidates in all (seeded per (scene, family)); candidates naming
    an object whose twin shows in one of their images (:meth:`~spacedg.qa.twins.TwinCheck.has_twin`) are
    left out and counted in ``twins`` per family. The family runs inside
    :func:`~spacedg.plugins.candidates.light_candidates` and :func:`~spacedg.plugins.candidates.gated`:
    the built-in families ask the pool (:func:`~spacedg.plugins.candidates.admitted`) before they
    draw for a valid candidate, and yield :data:`~spacedg.plugins.candidates.PASSED_OVER` for one
    it refuses (counted as scanned, in its stream's turn, as the candidate itself was before), so
    a candidate the pool would pass over costs its checks but none of its draws or its record; they yield
    :class:`~spacedg.plugins.candidates.Candidate` objects, pooled as :class:`~spacedg.qa.pooled.Pooled`
    (their selection entry only), so a record is built only for the candidates the selection takes;
    records a family yields as such (third-party families) are made inside
    :func:`~spacedg.plugins.qa_record.deferred_geometry`, their ``geometry`` converted to plain
    JSON types only once selected (:func:`_family_records`).

    ``stop_early`` (no judge): a family that declares ``metric_only``, or ``plain_rounds`` (without
    partial rounds), stops scanning once the selection could take nothing else
    (:meth:`_PoolScan.pooled`); the pool is then that prefix, and the selection takes the same records from it."""
    rng = np.random.default_rng(derive_seed(config.seed, scene.id, family.name))
    scan = _PoolScan(family, config, index, twins, stop_early)
    promised = scan.metric is not None or scan.cell_subs is not None  # a family held to metric_only or plain_rounds
    pooled: list[QARecord] = []
    with plugin_call("question family", family, "generate"), deferred_geometry(), light_candidates(), gated(scan.gate):
        try:
            for item in family.generate(scene, rng):
                if item is PASSED_OVER:
                    scan.passed_over()
                    continue
                if type(item) is Candidate:
                    if not scan.take(item.sub_question_type, item.views, item.subject, item.named):
                        continue
                    item = Pooled(item, family, scene.id)  # type: ignore[assignment]
                elif not scan.take(item.sub_question_type, item.views, _subject(item), named_ids(item)):
                    continue
                pooled.append(item)
                if promised:
                    scan.pooled(item, pooled)
        except _ScanDone:
            pass
    return pooled


def _subject(record: QARecord) -> str:
    """The pool's subject of a record: its selection subject, else its id."""
    sel = selection_of(record)
    return str(sel["subject"]) if sel is not None else f"record:{record.id}"


def _judged(record: QARecord, judge: DescriptionJudge | None, dropped: dict[str, int] | None, family_name: str) -> bool:
    """Whether ``judge`` keeps ``record`` (always without one); a drop is counted in ``dropped``."""
    if judge is None or judge.keep(record.record() if isinstance(record, Pooled) else record):
        return True
    if dropped is not None:
        dropped[family_name] = dropped.get(family_name, 0) + 1
    return False


def _family_records(
    family: Any, scene: Scene, config: QABuildConfig, judge: DescriptionJudge | None,
    dropped: dict[str, int] | None, selection_stats: dict[str, dict[str, int]] | None,
    index: TwinCheck, twins: Counter[str],
) -> list[QARecord]:
    """One family's records for the index: pooled, selected, dealt, in its sub-type order."""
    keep = functools.partial(_judged, judge=judge, dropped=dropped, family_name=family.name)
    stats: dict[str, Counter[str]] = {}
    pool = _pool(family, scene, config, index, twins, stop_early=judge is None)
    chosen = select_records(pool, quota(config.per_sub_type, config.mode), keep, stats, mode=config.mode, partial_rounds=config.partial_rounds)
    with plugin_call("question family", family, "generate"):
        chosen = [r.materialised() for r in chosen]  # geometry converted for the kept records only
    chosen = deal_distractors(chosen, np.random.default_rng(derive_seed(config.seed, scene.id, family.name, "distractors")))
    chosen = deal_letters(chosen, np.random.default_rng(derive_seed(config.seed, scene.id, family.name, "letters")))
    by_sub: dict[str, list[QARecord]] = {}
    for r in chosen:
        by_sub.setdefault(r.sub_question_type, []).append(r)
    if selection_stats is not None:
        for sub, row in stats.items():
            selection_stats[f"{family.name}/{sub}"] = dict(sorted(row.items()))
    return [r for sub in family.sub_question_types for r in by_sub.get(sub, [])]


def generate_records(
    scene: Scene,
    config: QABuildConfig = QABuildConfig(),
    *,
    judge: Any = None,
    dropped: dict[str, int] | None = None,
    selection_stats: dict[str, dict[str, int]] | None = None,
    twins: dict[str, int] | None = None,
) -> list[QARecord]:
    """Records of every selected family for a prepared scene (see the module docstring).

    Per family, candidates are pooled (up to ``pool_factor × per_sub_type`` distinct subjects
    per sub type, :data:`ALTERNATES` records each, ``max_scan`` candidates in all); then
    :func:`~spacedg.qa.selection.select_records` takes up to ``per_sub_type`` per sub type: each
    subject once, whole rounds of every cell's roles (no answer is predictable from what the
    text shows), metric answers in generation order; the kept sector-label MCQs get their
    distractors dealt again (:func:`~spacedg.qa.deal.deal_distractors`, seeded by
    ``derive_seed(seed, scene, family, "distractors")``) and the kept MCQ records their correct
    letters (:func:`~spacedg.qa.deal.deal_letters`, seeded by ``derive_seed(seed, scene, family,
    "letters")``), so letters are uniform per sub type.

    ``judge``: a callable ``judge(image, label, description) -> "KEEP"/"DROP"`` or a
    :class:`~spacedg.qa.judge.DescriptionJudge`, asked only about records being taken;
    ``dropped`` receives per-family counts of records the judge removed; ``selection_stats``
    receives per ``question_type/sub_question_type`` the counts of
    :func:`~spacedg.qa.selection.select_records`; ``twins`` per family the candidates left
    out because an object they name has a same-description twin in one of their images
    (:mod:`spacedg.qa.twins`). ``config.mode`` picks the strict bench or the dense train
    selection (:mod:`spacedg.qa.modes`).
    """

    if judge is not None and not isinstance(judge, DescriptionJudge):
        judge = DescriptionJudge(scene, judge)
    found: Counter[str] = Counter()
    out: list[QARecord] = []
    # The cyclic collector re-scanning the pools took a quarter of generation: paused, unless a
    # judge runs (it renders and may call a model, whose cyclic garbage must not wait for the scene's end).
    # The families' VisibilityIndex objects of the scene share one classification per thresholds (the scene does not change here).
    with collector_paused() if judge is None else contextlib.nullcontext(), shared_visibility_tables():
        index = TwinCheck(VisibilityIndex(scene))
        for family in selected_families(config.families):
            out.extend(_family_records(family, scene, config, judge, dropped, selection_stats, index, found))
    if twins is not None:
        twins.update(sorted(found.items()))
    return out


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
    the full index, or with ``config.families`` the selection index beside it
    (:func:`~spacedg.qa.index.index_paths`)."""

    scene_dir = Path(scene_dir)
    scene = load_scene(scene_dir)
    scene_json = scene_json_path(scene_dir)
    key = index_key(scene_json, config, selected_families(config.families), judge)
    jsonl, meta_path = config_index_paths(scene.id, out_dir if out_dir is not None else scene_json.parent, config)
    if not force and is_current(jsonl, meta_path, key):
        meta = read_meta(meta_path) or {}
        return SceneQA(scene.id, jsonl, read_index(jsonl), reused=True, seconds=dict(meta.get("seconds", {})))
    timings: dict[str, float] = {}
    prepared = prepare_scene(scene, scene_json.parent / "cache", config, backend=backend, progress=progress, timings=timings, device=device)
    dropped: dict[str, int] = {}
    selection: dict[str, dict[str, int]] = {}
    twins: dict[str, int] = {}
    t0 = time.perf_counter()
    records = generate_records(prepared, config, judge=judge, dropped=dropped, selection_stats=selection, twins=twins)
    timings["generate_s"] = time.perf_counter() - t0
    meta = {
        "format": "spacedg-qa-index", "version": QA_INDEX_VERSION, "key": key, "scene_id": scene.id,
        "config": config.to_dict(), "records": len(records),
        "counts": dict(sorted(Counter(r.question_type for r in records).items())),
        "dropped_by_judge": dropped, "twins": twins, "selection": selection, "seconds": {k: round(v, 4) for k, v in timings.items()},
    }
    write_index(jsonl, meta_path, records, meta)
    return SceneQA(scene.id, jsonl, records, reused=False, seconds=timings, dropped=dropped)


# --------------------------------------------------------- many scenes, isolated
def _build_indexes(payload: dict[str, Any]) -> dict[str, str]:
    """Child side of :func:`ensure_indexes`: build the indexes of ``payload["dirs"]``; returns
    ``folder → error message`` for the scenes that failed."""
    from tqdm import tqdm

    cfg = QABuildConfig.from_dict(payload["config"])
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
        failed.update(run_isolated("spacedg.qa.build:_build_indexes", {"dirs": stale, "config": config.to_dict()}))
    return failed

"""The debiased selection: which of a family's pooled candidates a scene's question index keeps.

:func:`select_records` takes up to ``per_sub_type`` records per sub type so that no function of
what a question's text shows beats chance in the scene (the blind stress test
:mod:`spacedg.qa.audit` measures what is left). It reads each candidate's ``selection`` entry
(:func:`~spacedg.plugins.questions.records.selection_entry`): the *subject* (an object, a pair,
a view and label), the *cell* (what a text-only model can tell about the question: its labels,
its option set, the axes it names), the *role* (its answer), the cell's ``roles`` and the
``features`` (the labels a size comparison names, by position). The steps, in this order:

1. metric answers (an entry without a cell): generation order, each subject once
   (:meth:`_Selection.take_metric`);
2. cells: whole rounds, one record of every role, cells visited round-robin
   (:meth:`_Selection.take_rounds`; a role is filled by :meth:`_Selection.pick`, which balances
   features across roles with :meth:`_Selection.cost`); for a bench balanced across its scenes
   afterwards, partial rounds too (:meth:`_Selection.take_partial_rounds`);
3. sub types whose quota is smaller than every round of their cells: their first free
   candidates (:meth:`_Selection.take_small_quotas`);
4. records without a ``selection`` entry (third-party families): round-robin over their
   correct answers (:func:`select_balanced`).
"""

from __future__ import annotations

import math
import zlib
from collections import Counter
from collections.abc import Callable, Container, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from spacedg.plugins.qa_record import QARecord
from spacedg.plugins.specs import AnswerType
from spacedg.qa.modes import subject_key

__all__ = ["truth_key", "selection_of", "features_of", "role_excess", "select_balanced", "select_records", "prefix_settles"]

Keep = Callable[[QARecord], bool]


def truth_key(record: QARecord) -> str | None:
    """What answer balancing groups by: the correct option's text (MCQ), the answer (YN, COUNT),
    or ``None`` for metric answers (NA, SIZE_LIST), which are not balanced."""
    if record.answer_type is AnswerType.MCQ:
        letter = str(record.answer)
        return next((o[3:] for o in record.options if o.startswith(letter + ". ")), letter)
    if record.answer_type in (AnswerType.YN, AnswerType.COUNT):
        return str(record.answer)
    return None


def selection_of(record: QARecord) -> dict[str, Any] | None:
    """The record's ``selection`` entry (a mapping with a ``subject``), or ``None``."""
    entry = record.geometry.get("selection")
    return entry if isinstance(entry, dict) and "subject" in entry else None


def features_of(record: QARecord) -> list[str]:
    """The ``features`` of the record's selection entry (what its text names: labels by position)."""
    return _entry_features(selection_of(record))


def _entry_features(entry: Mapping[str, Any] | None) -> list[str]:
    """:func:`features_of` from the selection entry itself."""
    features = entry.get("features") if entry is not None else None
    return list(map(str, features)) if isinstance(features, list) else []


def select_balanced(pool: list[QARecord], cap: int, keep: Keep) -> list[QARecord]:
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


@dataclass
class _Pool:
    """The candidates, indexed by position (generation order), sorted into the kinds the steps treat."""

    records: Sequence[QARecord]
    selections: list[dict[str, Any] | None] = field(default_factory=list)
    features: list[list[str]] = field(default_factory=list)
    subjects: list[tuple[str, str] | None] = field(default_factory=list)
    plain: dict[str, list[int]] = field(default_factory=dict)  # sub type → records without an entry
    metric: list[int] = field(default_factory=list)  # entries without a cell
    cells: dict[str, dict[str, list[int]]] = field(default_factory=dict)  # cell → role → records
    cell_roles: dict[str, list[str]] = field(default_factory=dict)  # cell → the roles of a round
    cell_keys: list[str | None] = field(default_factory=list)  # each record's cell (None: no cell)
    offered_roles_only: set[str] = field(default_factory=set)  # cells whose rounds go over the roles the scene offers (all_roles false)

    @classmethod
    def of(cls, records: Sequence[QARecord], mode: str = "bench") -> _Pool:
        pool = cls(records)
        selections, features, subjects = pool.selections, pool.features, pool.subjects
        cells, cell_roles, cell_keys = pool.cells, pool.cell_roles, pool.cell_keys
        partial: set[str] = set()
        for i, r in enumerate(records):  # one pass: the entry, features and subject key of each record
            sel = selection_of(r)
            selections.append(sel)
            if sel is None:
                features.append([])
                subjects.append(None)
                cell_keys.append(None)
                pool.plain.setdefault(r.sub_question_type, []).append(i)
                continue
            features.append(_entry_features(sel))
            subjects.append((r.sub_question_type, subject_key(str(sel["subject"]), r.views, mode)))
            if "cell" not in sel:
                cell_keys.append(None)
                pool.metric.append(i)
                continue
            cell = f"{r.question_type}|{sel['cell']}"
            cell_keys.append(cell)
            by_role = cells.get(cell)
            if by_role is None:
                by_role = cells[cell] = {}
                cell_roles[cell] = [str(x) for x in sel.get("roles", [])]
            role = str(sel["role"])
            queue = by_role.get(role)
            if queue is None:
                by_role[role] = [i]
            else:
                queue.append(i)
            if sel.get("all_roles", True) is False:
                partial.add(cell)
        for cell in partial:  # rounds over the roles this scene offers in the cell (at least two)
            offered = [role for role in pool.cell_roles[cell] if pool.cells[cell].get(role)]
            pool.cell_roles[cell] = offered if len(offered) >= 2 else []
        pool.offered_roles_only = partial
        return pool

    def subject(self, i: int) -> tuple[str, str]:
        return self.subjects[i]  # type: ignore[return-value]

    def sub(self, i: int) -> str:
        return self.records[i].sub_question_type

    def round_size(self, i: int) -> int:
        """How many records a round of record ``i``'s cell takes (1 outside cells)."""
        cell = self.cell_keys[i]
        if cell is None:
            return 1
        roles = self.cell_roles.get(cell) or self.selections[i].get("roles", [])  # type: ignore[union-attr] # a cell left without roles: the record's own
        return max(1, len(roles))


def role_excess(rows: Sequence[Mapping[str, int] | None], role: str, roles: Sequence[str]) -> float:
    """How over-represented a record's features are in ``role``: over its features' ``rows``
    (role → records taken with that feature; ``None``: none yet), the count in ``role`` minus the
    mean over ``roles``, summed (the greedy chi-square the selection and the pooled balance share)."""
    total = 0.0
    for row in rows:
        if row:
            total += row.get(role, 0) - sum(row.get(r, 0) for r in roles) / len(roles)
    return total


class _RoundsTrace:
    """What :meth:`_Selection.take_rounds` tells :func:`prefix_settles`: the room of every sub type
    after the first visit to every cell, and whether a cell lacked a candidate of a role (none
    left, or none at all) while its sub type still had room for its whole round (``unsure``: a
    later candidate of that role could have given the round)."""

    def __init__(self, cell_sub: Mapping[str, str], cell_roles: Mapping[str, Sequence[str]]) -> None:
        self.cell_sub = cell_sub  # cell → the one sub type of its records
        self.cell_roles = cell_roles
        self.first_sweep_room: dict[str, int] | None = None
        self.unsure = False

    def incomplete(self, cell: str, room: Mapping[str, int]) -> None:
        """``cell`` lacks a candidate of a role (none left, or none at all), with ``room`` per sub type:
        unsure if its sub type has room for its whole round."""
        if room[self.cell_sub[cell]] >= len(self.cell_roles[cell]):
            self.unsure = True


class _Selection:
    """The state of one :func:`select_records` call: what is taken, which subjects are asked,
    the room left per sub type, and the features each role has had (see the module docstring)."""

    def __init__(self, records: Sequence[QARecord], per_sub_type: int, keep: Keep | None, mode: str = "bench") -> None:
        self.pool = _Pool.of(records, mode)
        self.per_sub_type = per_sub_type
        self.keep = keep or (lambda record: True)
        self.judged_out: set[int] = set()  # pool positions the judge refused (a pooled record's id needs the record built)
        self.room: Counter[str] = Counter()
        for r in records:
            self.room[r.sub_question_type] = per_sub_type
        self.taken: set[int] = set()
        self.asked: set[tuple[str, str]] = set()
        cells = self.pool.cells
        self.cursors = {cell: {role: 0 for role in roles} for cell, roles in self.pool.cell_roles.items()}
        # feature balance: (sub type, feature) → role → records taken (features: what the text names)
        self.balance: dict[tuple[str, str], Counter[str]] = {}
        self.featured = {cell: any(self.pool.features[i] for q in by_role.values() for i in q) for cell, by_role in cells.items()}

    def accept(self, i: int) -> bool:
        """Whether the judge keeps pool record ``i`` (asked once; a refusal is remembered)."""
        if i in self.judged_out:
            return False
        if self.keep(self.pool.records[i]):
            return True
        self.judged_out.add(i)
        return False

    def take(self, i: int) -> None:
        self.taken.add(i)
        self.asked.add(self.pool.subject(i))
        self.room[self.pool.sub(i)] -= 1

    def take_metric(self) -> None:
        """Metric answers: generation order, subjects once."""
        pool = self.pool
        for i in pool.metric:
            if self.room[pool.sub(i)] > 0 and pool.subject(i) not in self.asked and self.accept(i):
                self.take(i)

    def cost(self, i: int, role: str, roles: Sequence[str]) -> float:
        """How over-represented record i's features already are in ``role`` (greedy chi-square)."""
        sub = self.pool.sub(i)
        return role_excess([self.balance.get((sub, f)) for f in self.pool.features[i]], role, roles)

    def _usable(self, i: int, used: Container[tuple[str, str]] = ()) -> bool:
        """Whether record ``i``'s subject is free (not asked, not in ``used``) and the judge has not refused it."""
        subject = self.pool.subject(i)
        return subject not in self.asked and subject not in used and i not in self.judged_out

    def pick(self, cell: str, role: str, used: set[tuple[str, str]]) -> int | None:
        """The candidate of ``role`` in ``cell`` for the next round: free subject, accepted by the
        judge; among them the least over-represented features (ties: generation order)."""
        queue = self.pool.cells[cell].get(role, [])
        k = self.cursors[cell][role]
        while k < len(queue) and not self._usable(queue[k]):
            k += 1  # never usable again
        self.cursors[cell][role] = k
        featured = self.featured[cell]
        while True:
            best, best_cost = None, math.inf
            for i in queue[k:]:
                if not self._usable(i, used):
                    continue
                c = self.cost(i, role, self.pool.cell_roles[cell]) if featured else 0.0
                if c < best_cost:
                    best, best_cost = i, c
                    if not featured:
                        break
            if best is None:
                return None
            if self.accept(best):
                return best

    def next_round(self, cell: str, trace: _RoundsTrace | None = None) -> list[int] | None:
        """One record per role of ``cell`` (distinct subjects), or ``None`` when a role has no
        candidate left or a sub type the round touches has no room for it. ``trace``: told
        when a role has no candidate left (:meth:`_RoundsTrace.incomplete`)."""
        round_: list[int] = []
        used: set[tuple[str, str]] = set()
        need: Counter[str] = Counter()
        for role in self.pool.cell_roles[cell]:
            i = self.pick(cell, role, used)
            if i is None:
                if trace is not None:
                    trace.incomplete(cell, self.room)
                return None
            round_.append(i)
            used.add(self.pool.subject(i))
            need[self.pool.sub(i)] += 1
        if any(self.room[sub] < n for sub, n in need.items()):
            return None
        return round_

    def take_round(self, round_: Sequence[int]) -> None:
        for i in round_:
            self.take(i)
            role = str(self.pool.selections[i]["role"])  # type: ignore[index]
            for f in self.pool.features[i]:
                self.balance.setdefault((self.pool.sub(i), f), Counter())[role] += 1

    def take_rounds(self, trace: _RoundsTrace | None = None) -> None:
        """Balanced cells: whole rounds, one per cell per visit, round-robin until none gives a round
        (``trace``: told of every role found without a candidate and of the room after the first visit to every cell)."""
        cells, roles = self.pool.cells, self.pool.cell_roles
        # a cell needs two roles at least: a one-role cell would be answered by its text alone
        open_cells = [c for c in cells if len(roles[c]) >= 2 and all(cells[c].get(role) for role in roles[c])]
        visits, lacking = open_cells, set()
        if trace is not None:  # the first visits pass the cells that lack a role too, in their place, and tell the trace
            visits = [c for c in cells if len(roles[c]) >= 2]
            lacking = set(visits).difference(open_cells)
        while open_cells:
            still = []
            for cell in visits:
                if cell in lacking:
                    trace.incomplete(cell, self.room)  # type: ignore[union-attr]
                    continue
                round_ = self.next_round(cell, trace)
                if round_ is None:
                    continue  # the cell is exhausted, or a sub type it needs is full
                self.take_round(round_)
                still.append(cell)
            if trace is not None and trace.first_sweep_room is None:
                trace.first_sweep_room = dict(self.room)
            open_cells = visits = still

    def take_partial_rounds(self) -> None:
        """Partial rounds, for a bench that balances every cell's roles across its scenes
        (:func:`~spacedg.qa.cell_balance.balance_cells`): while a sub type has room left after
        its whole rounds, its cells are visited round-robin and each visit takes one free
        candidate of every role the cell still offers (the least over-represented features
        first, as in a whole round). A scene with a pair against its labels' prior and none with
        it then still gives the one it has, which another scene's surplus completes. Each visit
        starts at another role (a fixed offset per scene and cell, the CRC-32 of their names, then one on per visit), so a
        quota that ends inside a visit does not favour the same roles in every scene. Cells whose
        rounds go over the roles each scene offers (``all_roles`` false) take none: their roles
        differ by scene, so no pooled count could balance them; nor do cells whose sub type's
        quota is smaller than one of their rounds (:meth:`take_small_quotas` serves those)."""
        cells, roles = self.pool.cells, self.pool.cell_roles
        subs = {c: {self.pool.sub(i) for queue in by_role.values() for i in queue} for c, by_role in cells.items()}
        open_cells = [c for c in cells if len(roles[c]) >= 2 and c not in self.pool.offered_roles_only
                      and self.per_sub_type >= len(roles[c])]
        scene = self.pool.records[0].scene_id if self.pool.records else ""
        visits: Counter[str] = Counter()
        while open_cells:
            still = []
            for cell in open_cells:
                if all(self.room[sub] <= 0 for sub in subs[cell]):
                    continue  # no room left: asking the judge about its candidates would be wasted
                n = len(roles[cell])
                start = (zlib.crc32(f"{scene}|{cell}".encode()) + visits[cell]) % n
                visits[cell] += 1
                used: set[tuple[str, str]] = set()
                for role in roles[cell][start:] + roles[cell][:start]:
                    i = self.pick(cell, role, used)
                    if i is None or self.room[self.pool.sub(i)] <= 0:
                        continue
                    self.take_round([i])
                    used.add(self.pool.subject(i))
                if used:
                    still.append(cell)
            open_cells = still

    def _smallest_rounds(self) -> dict[str, int]:
        """Per sub type, the smallest round among its cells (cells of fewer than two roles: 10**9)."""
        smallest: dict[str, int] = {}
        for cell, by_role in self.pool.cells.items():
            size = len(self.pool.cell_roles[cell])
            for queue in by_role.values():
                for i in queue:
                    sub = self.pool.sub(i)
                    smallest[sub] = min(smallest.get(sub, size), size) if size >= 2 else smallest.get(sub, 10**9)
        return smallest

    def take_small_quotas(self) -> None:
        """A sub type whose quota is smaller than every round of its cells (a tiny per_sub_type,
        e.g. 1) would stay empty: it takes its first free candidates in generation order instead
        (too few to balance anyway)."""
        pool = self.pool
        got = Counter(pool.sub(i) for i in self.taken)
        if all(got[sub] or self.room[sub] <= 0 for sub in self.room):
            return  # every sub type has records, or no room: nothing to fill
        smallest = self._smallest_rounds()
        for i in sorted(i for by_role in pool.cells.values() for queue in by_role.values() for i in queue):
            sub = pool.sub(i)
            if got[sub] == 0 and 0 < self.room[sub] < smallest.get(sub, 0) and pool.subject(i) not in self.asked \
                    and self.accept(i):
                self.take(i)

    def take_plain(self) -> None:
        """Records of families without selection entries: :func:`select_balanced` per sub type."""
        records = self.pool.records
        for ix in self.pool.plain.values():
            first: dict[str, int] = {}
            for i in ix:
                first.setdefault(records[i].id, i)
            for r in select_balanced([records[i] for i in ix], self.per_sub_type, lambda r: self.accept(first[r.id])):
                self.taken.add(first[r.id])

    def stats(self) -> dict[str, Counter[str]]:
        """Per sub type: ``pooled`` and why each record was (not) taken (:func:`select_records`' ``stats``
        keys): ``taken``, ``judge`` (refused by the judge), ``repeat`` (its subject already asked),
        ``quota`` (no room for another round of its cell), else ``unbalanced``."""
        pool, taken, judged_out, asked, room = self.pool, self.taken, self.judged_out, self.asked, self.room
        subs = [r.sub_question_type for r in pool.records]
        counts = Counter(zip(subs, [
            "taken" if i in taken else "judge" if i in judged_out
            else "repeat" if subject is not None and subject in asked  # (a record without an entry has no subject)
            else "quota" if room[sub] < pool.round_size(i) else "unbalanced"
            for i, (sub, subject) in enumerate(zip(subs, pool.subjects))
        ]))
        out: dict[str, Counter[str]] = {}
        for sub, n in Counter(subs).items():  # sub types in the order of their first record
            out[sub] = Counter({"pooled": n})
        for (sub, reason), n in counts.items():
            out[sub][reason] = n
        return out


def prefix_settles(records: Sequence[QARecord], per_sub_type: int, mode: str, sub_question_types: Sequence[str]) -> bool:
    """Whether :func:`select_records` (no judge, no partial rounds) takes from ``records``, a family's
    candidates so far in generation order, exactly what it would take from them followed by any
    more candidates of that family, when the family declares ``plain_rounds``: each record has a
    selection entry with a subject and a cell, the records of a cell share one sub type of
    ``sub_question_types``, every role of a cell is asked (no ``all_roles`` false) and no entry has
    ``features``. ``per_sub_type`` is the quota (:func:`~spacedg.qa.modes.quota`).

    True only when all of these hold on ``records`` (each checked here):

    1. every declared sub type has records; every record is a cell's (none metric, none without
       an entry, no features), and each cell's records share one sub type;
    2. the rounds (:meth:`_Selection.take_rounds`): after the first visit to every cell (in the
       order of their first records), every sub type has taken records and has room for fewer
       than 2 more; and whenever a cell lacked a free candidate of a role, at its first visit
       (no candidate of the role at all) or in a round, its sub type had no room for its whole
       round anyway.

    Why that suffices: a pick takes the first free candidate of its role in generation order (no
    features: every cost is 0), so a pick that finds one here finds the same one among more
    candidates; a cell here keeps its place among more candidates (a cell is placed by its first
    record), and a cell first seen later comes after all of these; a pick that finds none here,
    or a cell that lacks a role here, belongs to a visit where the room refuses the round anyway
    (2); so every visit to a cell seen here goes as it goes here. A cell first seen later is
    visited first after the first visit to all of these, when no sub type has room for a round
    (every round has at least 2 roles), and a cell that gave no round is not visited again. The
    steps after the rounds take nothing (no partial rounds; every sub type has records, so the
    small-quota step returns at once; no metric or plain records). Only the selection's
    statistics differ: they count what was read.
    """
    if not records:
        return False
    selection = _Selection(records, per_sub_type, None, mode)
    pool = selection.pool
    subs = {r.sub_question_type for r in records}
    if pool.plain or pool.metric or pool.offered_roles_only or any(pool.features) or set(sub_question_types) - subs:
        return False
    cell_sub: dict[str, str] = {}
    for cell, by_role in pool.cells.items():
        of_cell = {pool.sub(i) for queue in by_role.values() for i in queue}
        if len(of_cell) != 1:
            return False
        cell_sub[cell] = of_cell.pop()
    trace = _RoundsTrace(cell_sub, pool.cell_roles)
    selection.take_rounds(trace)
    if trace.first_sweep_room is None or trace.unsure:
        return False
    got = Counter(pool.sub(i) for i in selection.taken)
    return all(got[sub] > 0 and trace.first_sweep_room[sub] < 2 for sub in subs)


def select_records(
    records: Sequence[QARecord], per_sub_type: int, keep: Keep | None = None, stats: dict[str, Counter[str]] | None = None,
    mode: str = "bench", partial_rounds: bool = False,
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

    ``mode``: what "the same subject" is (:func:`~spacedg.qa.modes.subject_key`): ``"bench"``
    asks an object at most once per sub type whatever the views, ``"train"`` once per views.

    ``partial_rounds``: after the whole rounds, a sub type with room left takes partial rounds
    (:meth:`_Selection.take_partial_rounds`): the candidates of a bench whose cells are balanced
    across its scenes afterwards (:func:`~spacedg.qa.cell_balance.balance_cells`); an index used
    on its own is built without them.

    ``stats`` (optional) receives per sub type: ``pooled``, ``taken``, and why the others were
    not: ``repeat`` (subject already asked), ``quota`` (its sub type has no room for another
    round of its cell), ``unbalanced`` (no complete round of its cell left), ``judge``.
    """
    selection = _Selection(records, per_sub_type, keep, mode)
    selection.take_metric()
    selection.take_rounds()
    if partial_rounds:
        selection.take_partial_rounds()
    selection.take_small_quotas()
    selection.take_plain()
    if stats is not None:
        for sub, row in selection.stats().items():
            stats.setdefault(sub, Counter()).update(row)
    return [records[i] for i in sorted(selection.taken)]

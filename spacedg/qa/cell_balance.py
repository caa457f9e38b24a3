"""Roles balanced across a bench's scenes: what partial rounds need before the blind pruning.

A scene's question index takes whole rounds per balancing cell (one record of every role:
:mod:`spacedg.qa.selection`), so within a scene a text-only model that knows the cell does no
better than chance. Some cells are rarely whole in one room: a size comparison's cell is the
prior its labels give (``prior:first|medium``: the object whose label sorts first is typically
25–60 % longer), and a room seldom holds a pair that goes *against* it, a pair that goes with it
and a tie at once (measured on 8 rooms of seed 7700: 10 whole rounds of the longest side, 30
records, where the same rooms pooled hold 19).

A bench is probed pooled (:mod:`spacedg.qa.debias`): what a blind model can learn is the
balance of each cell over the whole bench, not within one room. So the candidates of a pooled
bench take partial rounds too (:class:`~spacedg.qa.index.QABuildConfig` ``partial_rounds``),
and :func:`balance_cells` then keeps, per cell pooled over the bench's scenes, the same number of
records of every role (the smallest role's count). The records of whole rounds are balanced
already, so a cell whose candidates came in whole rounds loses nothing; a role that no scene
offers empties its cell. Which surplus records go: the roles' records whose features (the labels
a question names, by position) that role has had most, pooled (greedy, as the selection's
:meth:`~spacedg.qa.selection._Selection.cost`), ties by a seeded hash: a pure function of the
records and the seed, so every shard of a sharded export keeps the same; among equals, the correct
letter (yes/no, count bin) its sub type has most, so the letters stay as even as the scenes dealt them.
"""

from __future__ import annotations

from collections import Counter, defaultdict
from collections.abc import Sequence
from dataclasses import dataclass, field

from spacedg.plugins.qa_record import QARecord
from spacedg.qa.audit import answer_class
from spacedg.qa.debias_probe import stable_hash
from spacedg.qa.selection import features_of, role_excess, selection_of

__all__ = ["CellBalance", "balance_cells"]


@dataclass
class CellBalance:
    """:func:`balance_cells`'s outcome: the records kept (input order) and the records removed per
    sub type (``"question_type/sub_question_type" → n``)."""

    kept: list[QARecord]
    removed: dict[str, int] = field(default_factory=dict)


def _cell_roles(record: QARecord) -> tuple[str, str, tuple[str, ...]] | None:
    """``(question_type|cell, role, roles)`` of a record with a balancing cell, else ``None``."""
    entry = selection_of(record)
    if entry is None or entry.get("cell") is None or entry.get("role") is None:
        return None
    roles = tuple(str(r) for r in entry.get("roles", ()))
    if len(roles) < 2 or entry.get("all_roles", True) is False:
        return None  # a cell balanced over the roles each scene offers takes no partial rounds: left as it is
    return f"{record.question_type}|{entry['cell']}", str(entry["role"]), roles


def _features(record: QARecord) -> list[str]:
    """The record's selection features, an object's own (``first#12``: ids are a scene's) scoped by its scene."""
    return [f"{record.scene_id}/{f}" if "#" in f else f for f in features_of(record)]


def _trim_role(records: list[QARecord], role: str, surplus: int, balance: dict[str, Counter[str]],
               roles: Sequence[str], letters: Counter[str], seed: int, features: dict[str, list[str]],
               classes: dict[str, str]) -> set[str]:
    """The ids of ``surplus`` of ``records`` (one role of one cell) whose features ``role`` has had
    most relative to the cell's mean over ``roles`` (greedy, :func:`~spacedg.qa.selection.role_excess`;
    ties: the correct letter, yes/no or count bin the sub type has most, then a seeded hash);
    ``balance`` (feature → role → records) and ``letters`` (answer class → records) are updated;
    ``features`` / ``classes``: each record's (by id), computed once by the caller."""
    left = [r.id for r in sorted(records, key=lambda r: (stable_hash(seed, "cells", r.id), r.id))]
    gone: set[str] = set()
    for _ in range(surplus):
        k = max(range(len(left)), key=lambda i: (role_excess([balance[f] for f in features[left[i]]], role, roles), letters[classes[left[i]]], -i))
        rid = left.pop(k)
        gone.add(rid)
        letters[classes[rid]] -= 1
        for f in features[rid]:
            balance[f][role] -= 1
    return gone


def balance_cells(records: Sequence[QARecord], seed: int = 0) -> CellBalance:
    """Keep, per balancing cell pooled over ``records``' scenes, as many records of every role as its
    rarest role has (module docstring); records without a cell are all kept. A cell's roles are the
    union of its records' ``roles``; a record id given twice is kept once."""
    first: dict[str, QARecord] = {}
    for r in records:
        first.setdefault(r.id, r)
    unique = list(first.values())  # the first record of each id, in input order
    cells: dict[str, dict[str, list[QARecord]]] = defaultdict(lambda: defaultdict(list))
    cell_roles: dict[str, dict[str, None]] = defaultdict(dict)  # cell → its roles, in first-seen order
    features: dict[str, list[str]] = {}
    for r in unique:
        got = _cell_roles(r)
        if got is not None:
            cell, role, roles = got
            cells[cell][role].append(r)
            cell_roles[cell].update(dict.fromkeys(roles))
            features[r.id] = _features(r)
    classes = {r.id: answer_class(r) for r in unique}
    letters: dict[str, Counter[str]] = defaultdict(Counter)  # sub type → answer class → records
    for r in unique:
        letters[r.sub_question_type][classes[r.id]] += 1
    gone: set[str] = set()
    removed: Counter[str] = Counter()
    for cell in sorted(cells):
        by_role, roles = cells[cell], tuple(cell_roles[cell])
        low = min(len(by_role.get(role, ())) for role in roles)
        balance: dict[str, Counter[str]] = defaultdict(Counter)
        for role, rs in by_role.items():
            for r in rs:
                for f in features[r.id]:
                    balance[f][role] += 1
        for role in sorted(by_role):
            rs = by_role[role]
            surplus = len(rs) - low
            if surplus > 0:
                out = _trim_role(rs, role, surplus, balance, roles, letters[rs[0].sub_question_type], seed, features, classes)
                gone |= out
                removed.update(f"{r.question_type}/{r.sub_question_type}" for r in rs if r.id in out)
    return CellBalance([r for r in unique if r.id not in gone], dict(sorted(removed.items())))

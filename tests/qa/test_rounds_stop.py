"""A family that declares ``plain_rounds`` stops its scan once the selection of what it has read is
provably final (:func:`spacedg.qa.selection.prefix_settles`): the same records as the full scan,
fewer candidates read; a pooled record that breaks the promise is refused."""

from __future__ import annotations

from collections import Counter
from typing import Any, NamedTuple

import numpy as np
import pytest

from spacedg.errors import PluginError
from spacedg.plugins.candidates import offer
from spacedg.qa.build import _pool
from spacedg.qa.index import QABuildConfig, selected_families
from spacedg.qa.modes import quota
from spacedg.qa.selection import prefix_settles, select_records
from spacedg.qa.twins import TwinCheck
from spacedg.plugins.questions.view_sampling import VisibilityIndex

ROUNDS = ("cross_view_cardinal_direction", "object_existence_estimation", "object_proxy_cardinal_direction")


# ------------------------------------------------------------------ the proof, on random pools
class _Entry(NamedTuple):
    """What the selection reads of a pooled candidate (the attributes :class:`~spacedg.qa.pooled.Pooled` has)."""

    question_type: str
    sub_question_type: str
    views: tuple[str, ...]
    geometry: dict[str, Any]
    scene_id: str = "s"


def _random_family(rng: np.random.Generator) -> dict[str, Any]:
    """A random plain-rounds family: sub types, their cells (each of one sub type) and the roles of each cell."""
    subs = [f"s{k}" for k in range(int(rng.integers(1, 3)))]
    cells = {}
    for k in range(int(rng.integers(1, 6))):
        n_roles = int(rng.choice([1, 2, 2, 3, 4, 8]))
        cells[f"c{k}"] = (subs[int(rng.integers(len(subs)))], [f"r{j}" for j in range(n_roles)])
    return {"subs": subs, "cells": cells, "subjects": int(rng.integers(4, 40)), "skew": float(rng.uniform(0.0, 2.5))}


def _candidates(family: dict[str, Any], n: int, rng: np.random.Generator) -> list[_Entry]:
    """``n`` candidates of ``family``: cells and roles drawn unevenly (rare roles and cells), subjects repeating."""
    names = list(family["cells"])
    cell_weights = np.exp(-family["skew"] * np.arange(len(names)))
    out = []
    for _ in range(n):
        cell = names[int(rng.choice(len(names), p=cell_weights / cell_weights.sum()))]
        sub, roles = family["cells"][cell]
        role_weights = np.exp(-family["skew"] * np.arange(len(roles)))
        role = roles[int(rng.choice(len(roles), p=role_weights / role_weights.sum()))]
        entry = {"subject": f"o{int(rng.integers(family['subjects']))}", "cell": cell, "role": role, "roles": list(roles)}
        out.append(_Entry("demo", sub, (f"v{int(rng.integers(3))}",), {"selection": entry}))
    return out


def _taken(records: list[_Entry], per_sub_type: int, mode: str) -> list[int]:
    positions = {id(r): i for i, r in enumerate(records)}
    return [positions[id(r)] for r in select_records(records, per_sub_type, mode=mode)]


def test_a_settled_prefix_takes_what_any_longer_pool_takes() -> None:
    """Random plain-rounds pools (one or two sub types, cells of 1–8 roles, rare roles, repeated
    subjects, both modes, small and large quotas): wherever ``prefix_settles`` says so, the selection
    of the prefix equals the selection of the prefix followed by the family's real continuation and
    by continuations that bring new cells, rare roles and new subjects."""
    rng = np.random.default_rng(20261129)
    settled = unsettled = 0
    for _ in range(160):
        family = _random_family(rng)
        per_sub_type, mode = int(rng.choice([1, 2, 3, 5, 8, 12])), str(rng.choice(["bench", "train"]))
        pool = _candidates(family, int(rng.integers(10, 90)), rng)
        for n in range(1, len(pool) + 1, 3):
            if not prefix_settles(pool[:n], per_sub_type, mode, family["subs"]):
                unsettled += 1
                continue
            settled += 1
            expected = _taken(pool[:n], per_sub_type, mode)
            assert _taken(pool, per_sub_type, mode) == expected
            wider = {**family, "cells": {**family["cells"], "late": (family["subs"][0], ["r0", "r1"])}, "skew": 0.0,
                     "subjects": family["subjects"] + 20}
            for extra in (family, wider):
                assert _taken(pool[:n] + _candidates(extra, 60, rng), per_sub_type, mode) == expected
    assert settled > 100 and unsettled > 100  # both answers were exercised


def test_prefix_settles_refuses_what_its_proof_does_not_cover() -> None:
    def entry(sub: str, cell: str, role: str, subject: str, **more: Any) -> _Entry:
        return _Entry("demo", sub, ("v0",), {"selection": {"subject": subject, "cell": cell, "role": role, "roles": ["a", "b"], **more}})

    rounds = [entry("s", f"c{k}", role, f"o{k}{role}") for k in range(3) for role in "ab"]  # three cells of two roles
    assert prefix_settles(rounds, 5, "bench", ["s"]) and prefix_settles(rounds, 7, "bench", ["s"])  # one place left after the first visits
    assert not prefix_settles(rounds, 8, "bench", ["s"])  # room for a round after the first visits: a later cell could take it
    assert not prefix_settles(rounds, 5, "bench", ["s", "t"])  # a declared sub type without records
    assert not prefix_settles([*rounds, entry("s", "c", "a", "o9", features=["x"])], 5, "bench", ["s"])
    assert not prefix_settles([*rounds, entry("t", "c", "a", "o9")], 5, "bench", ["s", "t"])  # a cell of two sub types
    assert not prefix_settles([*rounds, _Entry("demo", "s", ("v0",), {"selection": {"subject": "m"}})], 5, "bench", ["s"])
    assert not prefix_settles([], 5, "bench", ["s"])
    # a cell lacking a role at its first visit while its sub type has room for its round
    early = [entry("s", "d", "a", "p0"), *rounds]
    assert not prefix_settles(early, 5, "bench", ["s"])
    assert prefix_settles([*rounds, entry("s", "d", "a", "p0")], 5, "bench", ["s"])  # placed after the room is used


# ------------------------------------------------------------------ the built-in families
@pytest.fixture(scope="module")
def room_scenes(qa_room_dirs):
    from spacedg.scene.io import load_scene
    from tests.room_qa import prepare_room

    return [prepare_room(load_scene(folder), folder / "cache") for folder in qa_room_dirs[:2]]


def _selected(scene, family, config, stop_early):
    pool = _pool(family, scene, config, TwinCheck(VisibilityIndex(scene)), Counter(), stop_early=stop_early)
    chosen = select_records(pool, quota(config.per_sub_type, config.mode), mode=config.mode)
    return pool, [r.materialised().to_dict() for r in chosen]


def test_the_built_in_families_that_declare_it() -> None:
    assert {f.name for f in selected_families(None) if f.plain_rounds} == set(ROUNDS)


@pytest.mark.parametrize("mode, per_sub_type", [("bench", 25), ("bench", 8), ("bench", 3), ("train", 25)])
@pytest.mark.parametrize("family", [f for f in selected_families(None) if f.name in ROUNDS], ids=lambda f: f.name)
def test_the_stop_keeps_the_records_of_the_full_scan(room_scenes, family, mode, per_sub_type) -> None:
    config = QABuildConfig(mode=mode, per_sub_type=per_sub_type)
    for scene in room_scenes:
        full_pool, full = _selected(scene, family, config, stop_early=False)
        stopped_pool, stopped = _selected(scene, family, config, stop_early=True)
        assert stopped == full and full
        assert [r.geometry["selection"] for r in stopped_pool] == [r.geometry["selection"] for r in full_pool[: len(stopped_pool)]]


def test_the_stop_reads_fewer_candidates(room_scenes) -> None:
    config = QABuildConfig()
    for name, share in (("object_proxy_cardinal_direction", 0.5), ("object_existence_estimation", 0.9)):
        family = next(f for f in selected_families(None) if f.name == name)
        full_pool, _ = _selected(room_scenes[0], family, config, stop_early=False)
        stopped_pool, _ = _selected(room_scenes[0], family, config, stop_early=True)
        assert len(stopped_pool) < share * len(full_pool), name


def _demo_family(kind: str, plain_rounds: bool = True):
    from spacedg.plugins.question_family import FamilyFactory
    from spacedg.plugins.specs import AnswerType, TaskGroup

    def generate(scene, rng):
        view = next(iter(scene.views))
        for k in range(40):
            subject, sub = f"object:{k}", "s"
            entry: dict[str, Any] = {"subject": subject, "cell": f"c{k % 3}", "role": "ab"[k // 3 % 2], "roles": ["a", "b"]}
            if k == 5:  # a candidate that breaks the promise, before any stop
                if kind == "metric":
                    entry = {"subject": subject}
                elif kind == "plain":
                    entry = {}
                elif kind == "features":
                    entry["features"] = ["object:chair"]
                elif kind == "offered":
                    entry["all_roles"] = False
                elif kind == "undeclared":
                    sub = "u"
                elif kind == "two_subs":
                    sub, entry["cell"] = "t", "c0"
            yield offer(sub, (view,), subject, (), lambda e=entry: e, lambda: None)

    return FamilyFactory(generate, name=f"demo_{kind}", task_group=TaskGroup.OBJECT_CENTRIC, answer_types={AnswerType.MCQ},
                         sub_question_types=("s", "t"), num_views=(1,), description="demo", plain_rounds=plain_rounds)()


@pytest.mark.parametrize("kind, what", [
    ("metric", "metric record"), ("plain", "without a selection entry"), ("features", "selection features"),
    ("offered", "all_roles false"), ("undeclared", "undeclared sub type 'u'"), ("two_subs", "sub type 't' in a cell of sub type 's'"),
])
def test_a_record_that_breaks_the_promise_is_refused(room_scenes, kind, what) -> None:
    index = TwinCheck(VisibilityIndex(room_scenes[0]))
    for stop in (True, False):  # held to its promise with a judge too (no stop then)
        with pytest.raises(PluginError, match=f"declares plain_rounds.*{what}"):
            _pool(_demo_family(kind), room_scenes[0], QABuildConfig(), index, Counter(), stop_early=stop)
    assert len(_pool(_demo_family(kind, plain_rounds=False), room_scenes[0], QABuildConfig(), index, Counter(), stop_early=True)) == 40


def test_partial_rounds_turn_the_stop_off(room_scenes) -> None:
    """The proof covers the selection without partial rounds (a judge turns it off too: test_metric_stop.py)."""
    family = next(f for f in selected_families(None) if f.name == "object_proxy_cardinal_direction")
    index = TwinCheck(VisibilityIndex(room_scenes[0]))
    stopped = _pool(family, room_scenes[0], QABuildConfig(), index, Counter(), stop_early=True)
    partial = _pool(family, room_scenes[0], QABuildConfig(partial_rounds=True), index, Counter(), stop_early=True)
    full = _pool(family, room_scenes[0], QABuildConfig(), index, Counter(), stop_early=False)
    assert len(stopped) < len(partial) == len(full)


def test_rounds_trace_leaves_the_plain_selection_alone() -> None:
    """``take_rounds`` with and without a trace takes the same records (the trace only watches)."""
    from spacedg.qa.selection import _RoundsTrace, _Selection

    rng = np.random.default_rng(7)
    for _ in range(40):
        family = _random_family(rng)
        pool = _candidates(family, 60, rng)
        plain, traced = _Selection(pool, 5, None), _Selection(pool, 5, None)
        plain.take_rounds()
        cell_sub = {f"demo|{cell}": sub for cell, (sub, _) in family["cells"].items()}
        traced.take_rounds(_RoundsTrace({c: cell_sub.get(c, "") for c in traced.pool.cells}, traced.pool.cell_roles))
        assert plain.taken == traced.taken


def test_the_stop_reads_a_cell_round_from_its_first_record(room_scenes) -> None:
    """The scan's cheap pre-check (can the first visits fill the quota yet?) counts a cell's round as the
    selection does, from its first record's roles, whatever later records of the cell list."""
    from spacedg.plugins.question_family import FamilyFactory
    from spacedg.plugins.specs import AnswerType, TaskGroup

    def generate(scene, rng):
        view = next(iter(scene.views))
        for k in range(100):
            roles = ["a", "b"] if k < 3 else ["b"]  # the cells' first records list both roles; later ones not
            entry = {"subject": f"object:{k}", "cell": f"c{k % 3}", "role": "ab"[k // 3 % 2], "roles": roles}
            yield offer("s", (view,), entry["subject"], (), lambda e=entry: e, lambda: None)

    family = FamilyFactory(generate, name="demo_roles", task_group=TaskGroup.OBJECT_CENTRIC, answer_types={AnswerType.MCQ},
                           sub_question_types=("s",), num_views=(1,), description="demo", plain_rounds=True)()
    index, config = TwinCheck(VisibilityIndex(room_scenes[0])), QABuildConfig(per_sub_type=5)
    stopped = _pool(family, room_scenes[0], config, index, Counter(), stop_early=True)
    full = _pool(family, room_scenes[0], config, index, Counter(), stop_early=False)
    assert len(stopped) < len(full) == 100
    keep = [r.geometry["selection"]["subject"] for r in select_records(stopped, 5)]
    assert keep == [r.geometry["selection"]["subject"] for r in select_records(full, 5)] and keep

"""Partial rounds in a scene's candidates and the roles balanced across a bench's scenes
(:func:`spacedg.qa.selection.select_records` ``partial_rounds``, :func:`spacedg.qa.cell_balance.balance_cells`)."""

from __future__ import annotations

from collections import Counter

import pytest

from spacedg.errors import ParameterError
from spacedg.plugins.qa_record import QARecord
from spacedg.plugins.questions.records import label_features, selection_entry
from spacedg.plugins.specs import AnswerType, TaskGroup
from spacedg.qa.cell_balance import balance_cells
from spacedg.qa.index import QABuildConfig
from spacedg.qa.selection import select_records

ROLES = ("first", "second", "same")


def _sized(scene: str, k: int, role: str, first: str = "chair", second: str = "table", cell: str = "prior:first|medium",
           **entry) -> QARecord:
    """A size comparison of pair ``k`` in ``scene`` whose truth is ``role`` in ``cell``."""
    return QARecord(
        id=f"{scene}-{k}", scene_id=scene, question_type="object_size_comparison", sub_question_type="longest_side_compare",
        task_group=TaskGroup.OBJECT_CENTRIC, answer_type=AnswerType.MCQ, views=("a", "b"), question=f"Which {scene} {k}?",
        options=("A. x", "B. y", "C. about the same"), answer="A",
        geometry={"selection": selection_entry(f"pair{k}", cell, role, ROLES,
                                               features=label_features(plain=False, first=first, second=second), **entry)},
    )


def _roles(records: list[QARecord]) -> Counter[str]:
    return Counter(r.geometry["selection"]["role"] for r in records)


def test_partial_rounds_take_the_roles_a_scene_offers_only_when_asked() -> None:
    # a room with pairs that go with the prior and ties, none against it: no whole round
    records = [_sized("s", k, "first") for k in range(5)] + [_sized("s", 10 + k, "same") for k in range(2)]
    assert select_records(records, per_sub_type=25) == []
    partial = select_records(records, per_sub_type=25, partial_rounds=True)
    assert _roles(partial) == Counter(first=5, same=2)
    assert len({r.geometry["selection"]["subject"] for r in partial}) == len(partial)  # a pair once
    assert len(select_records(records, per_sub_type=3, partial_rounds=True)) == 3  # the quota holds
    # whole rounds come first and are the same with or without partial rounds
    whole = records + [_sized("s", 20, "second")]
    plain = select_records(whole, per_sub_type=25)
    assert _roles(plain) == Counter(first=1, second=1, same=1)
    assert {r.id for r in plain} <= {r.id for r in select_records(whole, per_sub_type=25, partial_rounds=True)}


def test_balance_cells_evens_every_role_across_scenes_and_keeps_the_rest() -> None:
    a = [_sized("A", k, "first") for k in range(4)] + [_sized("A", 10, "same")]
    b = [_sized("B", k, "second") for k in range(2)] + [_sized("B", 10 + k, "same") for k in range(3)]
    strong = [_sized("A", 30 + k, "first", cell="prior:first|strong") for k in range(6)]  # no scene against a strong prior
    metric = QARecord(id="m", scene_id="A", question_type="object_bounding_size_estimation", sub_question_type="size",
                      task_group=TaskGroup.OBJECT_CENTRIC, answer_type=AnswerType.NA, views=("a",), question="How long?",
                      answer=1.0, geometry={"selection": selection_entry("object:1")})
    out = balance_cells([*a, *b, *strong, metric], seed=0)
    kept = [r for r in out.kept if r.question_type == "object_size_comparison"]
    assert _roles(kept) == Counter(first=2, second=2, same=2)
    assert metric in out.kept
    assert out.removed == {"object_size_comparison/longest_side_compare": 6 + 2 + 2}
    assert [r.id for r in out.kept] == [r.id for r in [*a, *b, *strong, metric] if r in out.kept]  # input order kept
    assert balance_cells([*a, *b], seed=0).kept == balance_cells([*a, *b], seed=0).kept  # seeded, a pure function
    # whole rounds are balanced already: nothing goes
    rounds = [_sized("C", 3 * k + i, role) for k in range(3) for i, role in enumerate(ROLES)]
    assert balance_cells(rounds).kept == rounds and balance_cells(rounds).removed == {}


def test_balance_cells_drops_the_features_a_role_has_had_most() -> None:
    # "first" has 4 chairs-first and 2 lamps-first; "second" and "same" have one of each
    first = [_sized("A", k, "first", "chair") for k in range(4)] + [_sized("A", 10 + k, "first", "lamp") for k in range(2)]
    others = [_sized("B", 20, "second", "chair"), _sized("B", 21, "second", "lamp"),
              _sized("B", 22, "same", "chair"), _sized("B", 23, "same", "lamp")]
    kept = balance_cells([*first, *others]).kept
    firsts = Counter(r.geometry["selection"]["features"][0] for r in kept if r.geometry["selection"]["role"] == "first")
    assert firsts == Counter({"first:chair": 1, "first:lamp": 1})


def test_balance_cells_leaves_cells_over_offered_roles_alone() -> None:  # (they took no partial rounds)
    offered = [_sized("A", k, "first", all_roles=False) for k in range(3)] + [_sized("A", 9, "same", all_roles=False)]
    assert balance_cells(offered).kept == offered


def test_partial_rounds_config() -> None:
    assert "partial_rounds" not in QABuildConfig().to_dict()  # the keys of indexes built without it are unchanged
    on = QABuildConfig(per_sub_type=50, partial_rounds=True)
    assert on.to_dict()["partial_rounds"] is True and QABuildConfig.from_dict(on.to_dict()) == on
    assert QABuildConfig.from_dict(QABuildConfig().to_dict()) == QABuildConfig()
    with pytest.raises(ParameterError, match="partial_rounds"):
        QABuildConfig(mode="train", partial_rounds=True)
    with pytest.raises(ParameterError, match="partial_rounds must be True or False"):
        QABuildConfig(partial_rounds="yes")  # type: ignore[arg-type]


def test_balance_cells_keeps_the_letters_even_among_equals() -> None:
    # "first" has three answered A and one answered B, the other roles C: the surplus goes from A
    def lettered(scene: str, k: int, role: str, letter: str) -> QARecord:
        r = _sized(scene, k, role)
        return QARecord(**{**r.__dict__, "answer": letter})

    first = [lettered("A", k, "first", "A") for k in range(3)] + [lettered("A", 3, "first", "B")]
    others = [lettered("B", 10 + k, role, "C") for k, role in enumerate(("second", "second", "same", "same"))]
    kept = balance_cells([*first, *others]).kept
    assert Counter(r.answer for r in kept if r.geometry["selection"]["role"] == "first") == Counter({"A": 1, "B": 1})


def test_partial_rounds_leave_cells_over_offered_roles_alone() -> None:
    # a cell balanced over the roles each scene offers: its whole rounds only, never a partial one
    offered = [_sized("A", k, "first", all_roles=False) for k in range(4)] + [_sized("A", 9, "same", all_roles=False)]
    assert _roles(select_records(offered, per_sub_type=25, partial_rounds=True)) == Counter(first=1, same=1)


def test_balance_cells_takes_the_union_of_roles_and_each_id_once() -> None:
    a = [_sized("A", k, role) for k, role in enumerate(("first", "second", "same"))]
    odd = QARecord(**{**a[0].__dict__, "id": "A-odd", "question": "Which odd?",
                      "geometry": {"selection": selection_entry("pair99", "prior:first|medium", "other", (*ROLES, "other"))}})
    out = balance_cells([*a, a[0], odd])  # a role only one record knows, and a record given twice
    assert [r.id for r in out.kept] == [*(r.id for r in a), "A-odd"] and out.removed == {}  # every role of the union has one
    lone = balance_cells([*a, _sized("B", 7, "first")])  # a second "first": the surplus goes
    assert _roles([r for r in lone.kept]) == Counter(first=1, second=1, same=1)


def test_bench_targets_share_max_questions_over_question_types_first() -> None:
    from spacedg.data.bench_debias import bench_targets

    sized = [_sized(s, k, "first") for s in ("A", "B") for k in range(30)]  # 2 scenes x 30 of one sub type
    few = [QARecord(id=f"c{k}", scene_id="A", question_type="object_counting", sub_question_type="count",
                    task_group=TaskGroup.OBJECT_CENTRIC, answer_type=AnswerType.COUNT, views=("a",), question=f"How many {k}?",
                    answer=k % 3) for k in range(4)]
    assert bench_targets([*sized, *few], 25) == {("object_counting", "count"): 4, ("object_size_comparison", "longest_side_compare"): 50}
    # 20 shared round-robin over the two question types, as --max-questions shares a bench without pruning
    assert bench_targets([*sized, *few], 25, 20) == {("object_counting", "count"): 4, ("object_size_comparison", "longest_side_compare"): 16}
    assert bench_targets([*sized, *few], 25, 6) == {("object_counting", "count"): 3, ("object_size_comparison", "longest_side_compare"): 3}


def test_partial_rounds_have_index_files_of_their_own() -> None:
    from spacedg.qa.index import index_paths

    pooled = QABuildConfig(per_sub_type=50, partial_rounds=True)
    assert pooled.file_mode == "pooled" and QABuildConfig().file_mode == "bench" and QABuildConfig(mode="train").file_mode == "train"
    assert index_paths("room", "/x", (), pooled.file_mode)[0].name == "room.qa-pooled.jsonl"
    assert index_paths("room", "/x", (), "bench")[0].name == "room.qa.jsonl"


def test_qa_audit_mode_pooled_balances_the_candidates_first(tmp_path, capsys) -> None:
    from spacedg.cli import main

    # scene A offers "first" and "same", scene B "second" and "same" twice: pooled, one round survives per role
    records = [_sized("room-a", 0, "first"), _sized("room-a", 1, "first"), _sized("room-a", 2, "same"),
               _sized("room-b", 0, "second"), _sized("room-b", 1, "same"), _sized("room-b", 2, "same")]
    for record in records:
        with open(tmp_path / f"{record.scene_id}.qa-pooled.jsonl", "a", encoding="utf-8") as f:
            f.write(record.to_json() + "\n")
    assert main(["qa", "audit", str(tmp_path), "--mode", "pooled", "--no-learned", "--debias"]) == 0
    text = capsys.readouterr().out
    assert "Blind stress test over 3 records of 2 scenes" in text
    assert "before the probe, roles balanced per cell across scenes: removed 3: object_size_comparison/longest_side_compare 3" in text
    assert main(["qa", "audit", str(tmp_path), "--no-learned"]) == 2  # the strict indexes are not there
    assert "--partial-rounds" not in capsys.readouterr().err
    assert main(["qa", "audit", str(tmp_path / "none"), "--mode", "pooled"]) == 2


def test_format_debias_names_sub_types_too_small_to_measure() -> None:
    from spacedg.qa.debias import MIN_MEASURABLE, debias, format_debias

    records = [_sized(s, k, role) for s in ("A", "B") for k, role in enumerate(ROLES * 3)]  # 18 records: < MIN_MEASURABLE
    text = format_debias(debias(records, learned=False))
    assert f"too few records to measure a blind bias to a few points (n < {MIN_MEASURABLE}; add scenes): longest_side_compare (n " in text

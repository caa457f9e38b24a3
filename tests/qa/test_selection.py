"""The index's selection helpers on hand-made records: distractor dealing and feature balance."""

from __future__ import annotations

from collections import Counter

import numpy as np

from spacedg.qa.deal import deal_distractors, deal_letters
from spacedg.qa.selection import select_records, truth_key
from spacedg.plugins.answers import MCQ_LETTERS
from spacedg.plugins.qa_record import QARecord
from spacedg.plugins.questions.records import label_features, selection_entry
from spacedg.plugins.specs import AnswerType, TaskGroup

SECTORS = ("front", "front-right", "right", "back-right", "back", "back-left", "left", "front-left")


def _mcq(k: int, truth: str, distractors: list[str], first: list[str], sub: str = "relpos_A_facing_B", **entry) -> QARecord:
    texts = [truth, *first]
    slot = k % 4
    texts = texts[1:slot + 1] + [truth] + texts[slot + 1:]
    return QARecord(
        id=f"r{k}", scene_id="s", question_type="camera_object_relative_direction", sub_question_type=sub,
        task_group=TaskGroup.CAMERA_OBJECT, answer_type=AnswerType.MCQ, views=("v",), question=f"Question {k}?",
        options=tuple(f"{MCQ_LETTERS[i]}. {t}" for i, t in enumerate(texts)), answer=MCQ_LETTERS[slot],
        geometry={"sector_label": truth, "selection": selection_entry(f"s{k}", sub, truth, SECTORS, distractors=distractors, **entry)},
    )


def _records(n: int = 64) -> list[QARecord]:
    rng = np.random.default_rng(3)
    out = []
    for k in range(n):
        truth = SECTORS[k % 8]
        i = SECTORS.index(truth)
        banned = SECTORS[(i + 1) % 8]  # a neighbour that may not be a distractor
        allowed = [t for t in SECTORS if t not in (truth, banned)]
        first = [t for t in ("front", "back", "left", "right", "front-left") if t in allowed][:3]  # "front" offered most: biased
        out.append(_mcq(k, truth, allowed, list(rng.permutation(first))))
    return out


def _offered(records: list[QARecord]) -> Counter[str]:
    return Counter(o[3:] for r in records for o in r.options)


def test_deal_distractors_keeps_truths_and_letters_and_balances_offers() -> None:
    records = _records()
    dealt = deal_distractors(records, np.random.default_rng(0))
    assert [r.id for r in dealt] == [r.id for r in records]
    for before, after in zip(records, dealt):
        assert after.answer == before.answer and truth_key(after) == truth_key(before)  # truth and its letter kept
        assert len(after.options) == 4 and len({o[3:] for o in after.options}) == 4
        assert [o[:3] for o in after.options] == ["A. ", "B. ", "C. ", "D. "]
        allowed = set(before.geometry["selection"]["distractors"])
        assert {o[3:] for o in after.options} - {truth_key(after)} <= allowed  # never the banned neighbour
        assert after.geometry == before.geometry
    offers = _offered(dealt)
    assert max(offers.values()) - min(offers.values()) <= 2  # every text offered about equally often
    assert max(_offered(records).values()) - min(_offered(records).values()) > 2  # (the input was not)
    # offered equally often and right equally often: no text is a better guess than another
    rate = {t: sum(truth_key(r) == t for r in dealt) / offers[t] for t in SECTORS}
    assert max(rate.values()) - min(rate.values()) < 0.05
    again = deal_distractors(records, np.random.default_rng(0))
    assert [r.options for r in again] == [r.options for r in dealt]  # seeded
    relettered = deal_letters(dealt, np.random.default_rng(1))
    assert [truth_key(r) for r in relettered] == [truth_key(r) for r in records]


def test_deal_distractors_leaves_other_records_alone() -> None:
    plain = _records(4)
    plain = [QARecord(**{**r.__dict__, "geometry": {"selection": selection_entry(r.id, "c", "front", SECTORS)}}) for r in plain]
    assert deal_distractors(plain, np.random.default_rng(0)) == plain


def _sized(k: int, role: str, first: str, second: str) -> QARecord:
    roles = ("first", "second", "same")
    return QARecord(
        id=f"z{k}", scene_id="s", question_type="object_size_comparison", sub_question_type="longest_side_compare",
        task_group=TaskGroup.OBJECT_CENTRIC, answer_type=AnswerType.MCQ, views=("a", "b"), question=f"Which {k}?",
        options=("A. x", "B. y", "C. about the same", "D. cannot be determined"), answer="A",
        geometry={"selection": selection_entry(f"pair{k}", "cell", role, roles, features=label_features(plain=False, first=first, second=second))},
    )


def test_rounds_balance_features_across_roles() -> None:
    # generation order puts the chair first whenever it is larger: the first candidates of each
    # role would give "first:chair" only the role "first"
    records, k = [], 0
    for role in ("first", "second", "same"):
        for label in ("chair", "chair", "chair", "lamp", "lamp", "lamp") if role == "first" else ("lamp", "lamp", "lamp", "chair", "chair", "chair"):
            records.append(_sized(k, role, label, "table"))
            k += 1
    chosen = select_records(records, per_sub_type=6)
    assert len(chosen) == 6
    by_role: dict[str, Counter[str]] = {}
    for r in chosen:
        sel = r.geometry["selection"]
        by_role.setdefault(sel["role"], Counter()).update(sel["features"])
    for feature in ("first:chair", "first:lamp"):
        counts = [by_role[role][feature] for role in ("first", "second", "same")]
        assert max(counts) - min(counts) <= 1, (feature, counts)


def test_label_features() -> None:
    assert label_features(anchor="Office_Chair", query="lamp") == ["anchor:office chair", "query:lamp", "label:lamp", "label:office chair"]
    assert label_features(plain=False, first="chair") == ["first:chair"]
